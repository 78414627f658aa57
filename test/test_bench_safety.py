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
