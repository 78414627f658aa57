"""The executor under faults, over DDS: executor and mock_hardware run
as processes from the mock launch file on a flat floor; ``tools.safety`` plays the planner and
records every command to the arm. The last test re-runs each scenario with one protection
removed (a ``sitecustomize`` the processes import patches it out) and checks that the scenario's
assertion then fails: the checks see what they claim to see.
"""

import os
import signal

import numpy as np
import pytest
import rclpy
from rclpy.context import Context

from tactile_dock_ros.nodes import executor_node
from tactile_dock_ros.tools import safety

pytestmark = pytest.mark.dds
FAST_DIAGNOSTICS = {"executor": {"diagnostics_period": 0.2}}
# Scheduling allowance on top of the 2-control-period bound: the test machine is shared (2
# cores, several suites at once: load averages above 20 seen); the README figures are the
# bench's distributions.
LOAD_SLACK_S = 0.15


def _dropouts(probe, env, rng) -> list[dict]:
    return [safety.dropout(probe, env, s, rng.uniform(0.0, 0.3)) for s in ("wrench", "pose")]


def _dropout_ok(row, env) -> bool:
    return (
        row.get("latency_s") is not None
        and row["latency_s"] <= 2 * env.control_period + LOAD_SLACK_S
        and row["moving_after_stop"] == 0
    )


def test_sensor_dropout_stops_the_arm_and_aborts_without_evidence(tmp_path):
    with safety.mock_floor(tmp_path, FAST_DIAGNOSTICS) as (probe, env, _):
        rows = _dropouts(probe, env, np.random.default_rng(0))
        final = probe.diagnostics()
    for row, stream in zip(rows, ("wrench", "tool_pose"), strict=True):
        assert _dropout_ok(row, env), row
        assert row["outcome"] == "ABORTED" and row["segments"] == 0, row
        assert f"sensor timeout: {stream}" in row["detail"]
        # /diagnostics: ERROR naming the stale stream during the dropout
        assert f"{stream} stale" in row["diagnostics_error"], row
    # ... and after it: the rates, the counts, the last fault.
    assert final["plans_aborted"] == "2" and final["plans_run"] == "2", final
    assert "sensor timeout: tool_pose" in final["last_fault"], final
    mock_rate = 200.0  # config/mock.yaml mock_hardware rate_hz; a loaded machine publishes less
    for key in ("tool_pose_rate_hz", "wrench_rate_hz"):
        assert 10.0 <= float(final[key]) <= 1.2 * mock_rate, final
    assert 10.0 <= float(final["control_rate_hz"]) <= 1.2 / env.control_period


def _envelope_failures(result) -> list:
    """What went wrong in ``safety.envelope_scenarios`` (those run): [] when all held."""
    failures = [row for row in result["refusals"] if not row["refused"]]
    force, two = result["force_fault"], result["two_plans"]
    if force and not (force["outcome"] == "ABORTED" and "above the limit" in force["detail"]):
        failures.append(force)
    if two and not (
        two["first"] == "NO_CONTACT" and "refused: another plan is running" in two["second"]
    ):
        failures.append(two)
    return failures + result["violations"]


def test_no_command_leaves_the_envelope(tmp_path):
    with safety.mock_floor(tmp_path, FAST_DIAGNOSTICS) as (probe, env, _):
        result = safety.envelope_scenarios(probe, env)
    assert len(result["refusals"]) == 7 and result["force_fault"] and result["two_plans"]
    assert result["moving_commands"] > 100  # the check saw the arm move
    failures = _envelope_failures(result)
    assert failures == [], failures[:10]


def _load(tmp_path):
    with safety.mock_floor(tmp_path, FAST_DIAGNOSTICS, record_sensors=False, amplify=10) as (
        probe, env, processes,
    ):  # fmt: skip
        result = safety.control_jitter(probe, env, burst_size=10)
        result["pid"] = processes["executor"].pid
        result["policies"] = _thread_policies(result["pid"])
        return result, env


def _thread_policies(pid: int) -> dict[int, tuple[int, int, int]]:
    """Thread id -> (scheduling policy, real-time priority, nice) of each thread of ``pid``."""
    tids = [int(t) for t in os.listdir(f"/proc/{pid}/task")]
    return {
        t: (
            os.sched_getscheduler(t),
            os.sched_getparam(t).sched_priority,
            os.getpriority(os.PRIO_PROCESS, t),
        )
        for t in tids
    }


def _real_time_allowed() -> bool:
    """Whether this process may take SCHED_FIFO (root or an rtprio limit), as the node would."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
    except OSError:
        return False
    os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
    return True


def _load_failures(result, env) -> list[str]:
    """Which of these failed: the plan ran to its end (or, on a machine so loaded that the
    mock stalled for longer than sensor_timeout, stopped for that reason), every other plan
    refused, the period kept."""
    starved = result["outcome"] == "ABORTED" and "sensor timeout" in (result["detail"] or "")
    checks = {
        f"outcome {result['outcome']}: {result['detail']}": (
            result["outcome"] == "NO_CONTACT" or starved
        ),
        f"{result['commands']} commands": result["commands"] >= 50,
        f"burst details {result['burst_details']}": (
            result["burst_details"] == ["refused: another plan is running"]
        ),
        # (a burst plan may follow)
        f"plans run {result['diagnostics']['plans_run']}": (
            result["diagnostics"]["plans_run"] == "1" or starved
        ),
        f"interval p50 {result['interval_s']['p50']:.4f} s": (
            result["interval_s"]["p50"] == pytest.approx(env.control_period, abs=2e-3)
        ),
        f"jitter p99 {result['jitter_s']['p99']:.4f} s": (
            result["jitter_s"]["p99"] <= 2 * env.control_period + LOAD_SLACK_S
        ),
    }
    return [name for name, ok in checks.items() if not ok]


def test_control_loop_keeps_its_period_under_10x_sensor_rate_and_plan_bursts(tmp_path):
    result, env = _load(tmp_path)
    assert result["burst_plans"] >= 40 and result["burst_reports"] >= 1, result
    # The executor received 10x what the mock published, less what a loaded machine drops
    # (best-effort sensor QoS; at a load average of 18 it still got 1.7x).
    for stream, rate in result["executor_rate_hz"].items():
        assert rate >= 1.3 * result["mock_rate_hz"], (stream, result)
    assert _load_failures(result, env) == [], result
    # the executor's own count (its diagnostics): the control thread keeps its period while
    # the main thread takes 10x the samples
    ticks = result["executor_ticks"]
    assert ticks["ticks"] >= 100 and ticks["late"] <= 0.05 * ticks["ticks"], ticks
    assert ticks["max_interval_s"] <= 5 * env.control_period + LOAD_SLACK_S, ticks
    # where the machine allows real time: the control loop's own thread SCHED_FIFO at
    # thread_priority, the main thread (samples, plans) not real-time but at nice -20
    policies = result["policies"]
    if _real_time_allowed():
        main = policies.pop(result["pid"])  # the main thread's id is the process id
        assert main == (os.SCHED_OTHER, 0, executor_node.CALLBACK_NICE), main
        assert [p[0] for p in policies.values()].count(os.SCHED_FIFO) == 1, policies


def _exit_ok(row) -> bool:
    return row.get("exit_code") == 0 and row.get("zero_command") and row["moving_after_zero"] == 0


@pytest.mark.parametrize("record_sensors", [True, False])
def test_the_probe_is_ready_only_once_it_recorded_a_pose_and_a_wrench(record_sensors):
    """Readiness includes the probe's own sensor subscriptions: ``executor_exit`` measures the
    tool's travel from the last pose before the signal, which a subscription that matched
    after the move began never received (distance None, seen in a fresh-clone CI run)."""
    context = Context()
    rclpy.init(context=context)
    try:
        probe = safety.Probe(context, record_sensors)
        waits = "pose and wrench recorded" in probe.not_ready()
        probe.rec.poses.append((0.0, np.zeros(3)))
        still = "pose and wrench recorded" in probe.not_ready()
        probe.rec.wrenches.append((0.0, np.zeros(3)))
        recorded = "pose and wrench recorded" in probe.not_ready()
        probe.destroy_node()
    finally:
        rclpy.shutdown(context=context)
    assert (waits, still, recorded) == ((True, True, False) if record_sensors else (False,) * 3)


def test_sigterm_of_the_executor_mid_move_commands_zero_before_it_exits(tmp_path):
    with safety.mock_floor(tmp_path, FAST_DIAGNOSTICS) as (probe, env, processes):
        row = safety.executor_exit(probe, env, processes, signal.SIGTERM, respawn=False)
    assert _exit_ok(row), row
    # the arm stopped at once: far less than the mock's command_timeout at 0.2 m/s
    assert row["distance_m"] is not None and row["distance_m"] < 0.02, row


NOT_BUSY = (
    "import tactile_dock_ros.nodes.executor_node as e\ne.ExecutorNode.busy = lambda s: False\n"
)
# Each protection, removed in the processes by a sitecustomize, and the scenario that must catch it.
MUTATIONS = {
    "workspace box": (
        "import tactile_dock_ros.execution.guarded as g\ng.Limits.inside = lambda self, p: True\n",
        "target outside the workspace",
    ),
    "speed limit": (
        "import dataclasses\nimport tactile_dock_ros.nodes.executor_node as e\n"
        "_L = e.Limits\ne.Limits = lambda *a: dataclasses.replace(_L(*a), max_speed=1e3)\n",
        "absurd speed (100 m/s)",
    ),
    "force limit": (
        "import dataclasses\nimport tactile_dock_ros.nodes.executor_node as e\n"
        "_L = e.Limits\ne.Limits = lambda *a: dataclasses.replace(_L(*a), max_force=1e3)\n",
        "force above the limit",
    ),
    "episode gate": (
        "import tactile_dock_ros.nodes.watchdog as w\n"
        "w.EpisodeGate.admit = lambda self, e: (w.Admission.RUN, '')\n",
        "plan of a superseded episode",
    ),
    "busy refusal": (
        NOT_BUSY,
        "two plans at once",
    ),
    "busy refusal under load": (
        NOT_BUSY,
        "load",
    ),
    "zero command on exit": (
        "import tactile_dock_ros.nodes.executor_node as e\ndel e.ExecutorNode.on_shutdown\n",
        "sigterm",
    ),
    "sensor timeout": (
        "import numpy\nimport tactile_dock_ros.nodes.watchdog as w\n"
        "w.StreamWatch.age = lambda self, now: 0.0 if self.last is not None else numpy.inf\n",
        "dropout",
    ),
}


@pytest.mark.slow  # each protection's own test runs by default; this checks those tests
@pytest.mark.parametrize("removed", MUTATIONS)
def test_each_check_fails_when_its_protection_is_removed(removed, tmp_path, monkeypatch):
    patch, scenario = MUTATIONS[removed]
    (tmp_path / "sitecustomize.py").write_text(patch)
    monkeypatch.setenv("PYTHONPATH", f"{tmp_path}:{__import__('os').environ['PYTHONPATH']}")
    if scenario == "load":
        result, env = _load(tmp_path / "run")
        assert _load_failures(result, env), result
        return
    with safety.mock_floor(tmp_path / "run", FAST_DIAGNOSTICS) as (probe, env, processes):
        if scenario == "sigterm":
            row = safety.executor_exit(probe, env, processes, signal.SIGTERM, respawn=False)
            assert not _exit_ok(row), row
            return
        if scenario == "dropout":
            rows = [safety.dropout(probe, env, "wrench", 0.1)]
            assert not _dropout_ok(rows[0], env), rows
            return
        result = safety.envelope_scenarios(probe, env, names=[scenario])
    assert _envelope_failures(result), result  # the check catches the unprotected executor
