"""Executor health without DDS: stream watch, episode gate, /diagnostics status, plan refusals."""

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticStatus
from hypothesis import given
from hypothesis import strategies as st

from tactile_dock_ros.execution.guarded import GuardedRun, Limits, Settings
from tactile_dock_ros.execution.types import Outcome, PlanCommand
from tactile_dock_ros.nodes.diagnostics import ExecutorHealth
from tactile_dock_ros.nodes.watchdog import Admission, EpisodeGate, StreamWatch


def test_stream_watch_age_rate_and_gap():
    watch = StreamWatch(window_s=1.0)
    assert watch.age(5.0) == np.inf and watch.max_gap(5.0) == np.inf and watch.rate(5.0) == 0
    for t in np.arange(0.0, 2.0, 0.01):  # 100 Hz for 2 s, then silence
        watch.add(float(t))
    assert watch.age(2.5) == pytest.approx(0.51)
    assert watch.rate(1.995) == pytest.approx(100.0, abs=1.0)
    assert watch.rate(2.5) == pytest.approx(49.0, abs=1.0)  # half the window is silent
    assert watch.max_gap(1.995) == pytest.approx(0.01, abs=1e-6)
    assert watch.max_gap(2.5) == pytest.approx(0.51)  # the open interval counts
    assert watch.count == 200 and len(watch._times) <= 102  # old samples leave the window
    with pytest.raises(ValueError):
        StreamWatch(0.0)


@given(st.lists(st.floats(0.0, 0.05), min_size=1, max_size=200))
def test_stream_watch_rate_counts_the_samples_in_the_window(gaps):
    times = np.cumsum(gaps)
    watch = StreamWatch(window_s=0.5)
    for t in times:
        watch.add(float(t))
    now = float(times[-1])
    assert watch.rate(now) == pytest.approx(np.sum(times > now - 0.5) / 0.5)
    assert watch.age(now) == 0.0


def test_episode_gate_admits_only_the_running_episode():
    gate = EpisodeGate()
    assert gate.admit(3)[0] is Admission.RUN  # no planner status seen: plans run as they come
    gate.update(5, "RUNNING")
    assert gate.admit(5)[0] is Admission.RUN
    decision, why = gate.admit(6)
    assert decision is Admission.WAIT and "6" in why  # its status may still be on the way
    gate.update(7, "RUNNING")
    assert gate.admit(5) == (Admission.REFUSE, "episode 5 was superseded by 7")
    gate.update(7, "GAVE_UP")
    assert gate.admit(7) == (Admission.REFUSE, "episode 7 is over")
    gate.update(7, "RUNNING")  # the same id running again (a planner that resumed it)
    assert gate.admit(7)[0] is Admission.RUN


def _values(status: DiagnosticStatus) -> dict:
    return {kv.key: kv.value for kv in status.values}


def test_diagnostics_level_names_the_stale_stream_and_reports_counts():
    health = ExecutorHealth(sensor_timeout=0.5, control_period=0.01)
    missing = health.status(0.0, "executor", "idle")
    assert missing.level == DiagnosticStatus.ERROR
    assert "tool_pose missing" in missing.message and "wrench missing" in missing.message
    for t in np.arange(0.0, 1.0, 0.005):
        health.streams["tool_pose"].add(float(t))
        health.streams["wrench"].add(float(t))
        if round(t / 0.005) % 2 == 0:
            health.ticks.add(float(t))
    ok = health.status(1.0, "executor", "running plan 2", {"episode": "4 RUNNING"})
    assert ok.level == DiagnosticStatus.OK and ok.message == "running plan 2"
    values = _values(ok)
    assert float(values["wrench_rate_hz"]) == pytest.approx(200.0, abs=2)
    assert float(values["control_rate_hz"]) == pytest.approx(100.0, abs=2)
    assert values["episode"] == "4 RUNNING" and values["plans_aborted"] == "0"
    assert ok.name == "executor: guarded moves" and ok.hardware_id == "executor"
    health.streams["tool_pose"].add(1.0)
    health.ticks.add(1.0)
    stale = health.status(1.7, "executor", "idle")  # wrench 0.705 s old, pose 0.7 s old
    assert stale.level == DiagnosticStatus.ERROR and "wrench stale 0.70 s" in stale.message
    assert health.oldest(1.7) == ("wrench", pytest.approx(0.705))
    health.streams["wrench"].add(1.7)
    health.streams["tool_pose"].add(1.7)
    health.fault(1.7, "plan 3: sensor timeout: wrench 0.51 s old")
    late = health.status(1.75, "executor", "idle")  # no control tick for 0.75 s
    assert late.level == DiagnosticStatus.WARN and "control loop late" in late.message
    assert _values(late)["last_fault"].startswith("plan 3: sensor timeout")


LIMITS = Limits(np.array([-0.9, -0.9]), np.array([0.9, 0.9]), 0.2, 40.0, 0.5)


@pytest.mark.parametrize(
    ("waypoints", "speed", "threshold", "why"),
    [
        ([[0.0, 0.3], [np.nan, 0.1]], 0.1, 3.0, "NaN"),
        ([[0.0, 0.3], [0.0, 0.1]], np.inf, 3.0, "NaN or inf"),
        ([[0.0, 0.3], [0.0, 0.1]], 0.0, 3.0, "> 0"),
        ([[0.0, 0.3], [0.0, 0.1]], 0.1, -1.0, "> 0"),
        ([[0.0, 0.3], [0.0, 0.1]], 5.0, 3.0, "exceeds the limit"),
        ([[0.0, 0.3], [0.95, 0.3], [0.95, 0.1]], 0.1, 3.0, "outside the workspace"),
    ],
)
def test_bad_plans_are_refused_before_any_motion(waypoints, speed, threshold, why):
    plan = PlanCommand(
        1, True, np.array(waypoints, float), np.array([0.0, -1.0]), threshold, speed, False,
        0.5, 0.5, 0, "",
    )  # fmt: skip
    run = GuardedRun(plan, np.array([0.0, 0.3]), LIMITS, Settings(), 0.0)
    assert run.done and run.outcome is Outcome.ABORTED and why in run.detail, run.detail
    velocity = run.check_next(
        np.array([0.0, 0.3]), run.step(0.01, np.zeros(2), np.zeros(2), 0), 0.01
    )
    assert np.all(velocity == 0.0) and len(run.history) == 0
