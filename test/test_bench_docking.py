"""The docking benchmark runs end to end on a tiny configuration and writes its JSON."""

import json

from tactile_dock_ros.tools import bench


def test_docking_bench_small(tmp_path):
    out = tmp_path / "docking.json"
    argv = ["docking", "--instances", "3", "--max-cycles", "4", "--problems", "notch"]
    assert bench.main([*argv, "--strategies", "ours", "gw", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert [r["strategy"] for r in report["results"]] == ["ours", "gw"]
    for row in report["results"]:
        assert row["instances"] == 3 and len(row["episodes"]) == 3
        times = [t for e in row["episodes"] for t in e["cycle_seconds"]]
        assert row["cycle_seconds_max"] == max(times)
        assert 0 < row["cycle_seconds_median"] <= row["cycle_seconds_max"]
        later = [t for e in row["episodes"] for t in e["cycle_seconds"][1:]]
        assert (row["later_cycle_seconds_median"] is None) == (not later)
