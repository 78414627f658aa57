"""bench safety runs end to end on a tiny configuration and writes its JSON (over DDS)."""

import json

import numpy as np
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


def test_side_by_side_thread_priorities_beside_cpu_burners(tmp_path):
    """One dropout per executor thread_priority (0: normal scheduler, 1: SCHED_FIFO where
    allowed) beside a CPU burner: both runs in one JSON, each with its load average."""
    out = tmp_path / "safety.json"
    argv = ["safety", "--parts", "dropout", "--dropouts", "1", "--cpu-burners", "1"]
    argv += ["--thread-priority", "0", "1", "--log-dir", str(tmp_path / "logs"), "--json", str(out)]
    assert bench.main(argv) == 0
    report = json.loads(out.read_text())
    assert report["cpu_burners"] == 1 and set(report["by_thread_priority"]) == {"0", "1"}
    for run in report["by_thread_priority"].values():
        assert run["dropout"]["summary"]["stopped"] == 1 and run["load_average"]["dropout"] > 0
    for bad in (["--thread-priority", "100"], ["--cpu-burners", "-1"]):
        with pytest.raises(SystemExit):
            bench.main(["safety", "--parts", "dropout", *bad])


def test_stop_latency_without_samples_is_reported_not_raised():
    from tactile_dock_ros.tools import safety

    zero, moving = np.zeros(3), np.array([0.1, 0.0, 0.0])
    empty = safety.stop_latency([], [(1.0, zero, 1.0)], 0.5)
    assert empty["latency_s"] is None and "no sample" in empty["error"]
    commands = [(1.2, moving, 0.0), (1.6, zero, 0.0), (1.7, moving, 0.0)]
    row = safety.stop_latency([(0.9, None), (1.0, None)], commands, 0.5)
    assert row == {"latency_s": pytest.approx(0.1), "moving_after_stop": 1}
    no_zero = safety.stop_latency([(1.0, None)], commands[:1], 0.5)
    assert no_zero == {"latency_s": None, "moving_after_stop": 0}
