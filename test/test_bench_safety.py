"""bench safety runs end to end on a tiny configuration and writes its JSON (over DDS)."""

import json

import pytest

from tactile_dock_ros.tools import bench

pytestmark = pytest.mark.dds


def test_safety_bench_dropout_small(tmp_path):
    out = tmp_path / "safety.json"
    argv = ["safety", "--parts", "dropout", "--dropouts", "2", "--log-dir", str(tmp_path / "logs")]
    assert bench.main([*argv, "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    summary = report["dropout"]["summary"]
    assert [r["stream"] for r in report["dropout"]["rows"]] == ["wrench", "pose"]
    assert summary["dropouts"] == 2 and summary["stopped"] == 2 and summary["aborted"] == 2
    latencies = [r["latency_s"] * 1e3 for r in report["dropout"]["rows"]]
    assert summary["latency_ms"]["max"] == pytest.approx(max(latencies))
    assert summary["aborted_with_segments"] == 0 and summary["moving_after_stop"] == 0
    assert "envelope" not in report and "load" not in report
