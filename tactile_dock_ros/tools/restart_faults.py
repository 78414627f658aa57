"""Fault injection: kill -9 the inference or the planner node mid-episode, start it again.

    python -m tactile_dock_ros.tools.restart_faults [--node inference planner] [--repeat N]
        [--seed 5] [--json OUT]

Brings up the mock profile (five processes, ``tools.bringup``), starts an episode and, once the
second plan is out and the arm moves on it (the history holds the first attempt's evidence),
SIGKILLs the node, waits for what happens without it, then starts it again with the same launch
settings and waits until the planner publishes its next plan. Measured per run:

* ``history_before``: contact_history segments before the kill; ``history_after``: segments of
  the next plan's history (``DockingPlan.history_length``), ``history_expected``: the segments
  of every report of the episode so far; ``history_kept``: the pre-kill rows are unchanged in
  the restarted suite's history (bit-exact);
* ``same_episode``: the next plan carries the episode id of before the kill;
* planner only: ``stop_s``, from the kill to the executor's report that it stopped the arm
  (``execution.types.PRODUCER_LOST``), and ``stopped``: every arm command from then until the
  restart is zero;
* ``resume_s``: from the restart to the next plan (wall clock: startup, discovery, journal
  replay, sampling and planning on this machine);
* inference only: ``warm_start_restored``, the restarted node sampled warm from the posterior
  its killed predecessor saved (its log says "warm start restored"; ``nodes.warm_start``).

The executor's ``producer_timeout`` is set to ``PRODUCER_TIMEOUT_S`` (a config copy), so the
planner's death stops the arm before the running attempt would end on its own, and its
``sensor_timeout`` to ``SENSOR_TIMEOUT_S``: these runs are about restarts, and on a starved
machine the mock's 0.5 s aborted episodes before the fault (ABORTED, sensor timeout).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

PRODUCER_TIMEOUT_S = 1.5
SENSOR_TIMEOUT_S = 2.0
NODES = ("inference", "planner")


class EndedBeforeFault(RuntimeError):
    """The episode ended (or gave up) before its second plan moved the arm: no fault injected.
    The terrain and the episode's course decide it, not the node under test; try another seed."""


def _config(log_dir: Path) -> Path:
    from tactile_dock_ros.tools import bringup

    config = yaml.safe_load((bringup.PACKAGE_ROOT / "config" / "mock.yaml").read_text())
    executor = config["executor"]["ros__parameters"]
    executor["producer_timeout"], executor["sensor_timeout"] = PRODUCER_TIMEOUT_S, SENSOR_TIMEOUT_S
    path = log_dir / "mock_fault.yaml"
    path.write_text(yaml.safe_dump(config))
    return path


def run(node: str, log_dir: Path, seed: int = 5, timeout_s: float = 120.0) -> dict:
    """One fault-injection run on ``node`` (one of NODES); the measurements above."""
    import rclpy
    from geometry_msgs.msg import TwistStamped
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from tactile_dock_ros.msg import ContactHistory, DockingPlan, ExecutionReport
    from tactile_dock_ros.nodes import convert, qos
    from tactile_dock_ros.tools import bringup, episode

    if node not in NODES:
        raise ValueError(f"node {node!r} is not one of {NODES}")
    log_dir.mkdir(parents=True, exist_ok=True)
    arguments = {
        "profile": "mock",
        "problem": "sloper",
        "seed": str(seed),
        "prior_source": "problem",
        "config": str(_config(log_dir)),
    }
    histories, commands, reports = [], [], []  # (time.monotonic(), msg)
    context = Context()
    rclpy.init(context=context)
    client = episode.EpisodeClient(context=context)
    now = time.monotonic

    def keep(into):
        return lambda msg: into.append((now(), msg))

    client.create_subscription(ContactHistory, "/contact_history", keep(histories), qos.LATCHED)
    client.create_subscription(TwistStamped, "/arm/cmd_twist", keep(commands), qos.COMMAND)
    client.create_subscription(ExecutionReport, "/execution_report", keep(reports), qos.EVENTS)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(client)
    record = client.record

    def wait(what: str, done) -> None:
        if not client.spin_until(executor, done, timeout_s):
            raise TimeoutError(f"{node} fault run: timed out waiting for {what} (logs: {log_dir})")

    def dock_reports() -> list:  # (time, report) of the episode's attempts
        return [(t, r) for t, r in reports if r.episode == record.plans[0].episode]

    try:
        with bringup.running(arguments, log_dir) as processes:
            client.start(executor, timeout_s)
            ended = episode.FINAL_STATES

            def second_move():  # the second plan, if it docks (a GIVE_UP plan moves nothing)
                plans = record.plans[1:2]
                return plans[0] if plans and plans[0].decision == DockingPlan.DOCK else None

            wait("the second plan", lambda: second_move() is not None or record.state in ended)
            moved = second_move()
            if moved is None:  # e.g. a give-up at cycle 2, or a starved machine's timeout
                why = f"{record.state} {record.detail}"
                raise EndedBeforeFault(
                    f"the episode ended before the fault: {why} (logs: {log_dir})"
                )
            episode_id, killed_during = moved.episode, moved.plan_id
            t_plan = now()
            # The executor runs it (else nobody resends it while the planner is down).
            wait("the arm to move", lambda: any(t > t_plan and not _zero(m) for t, m in commands))
            before = convert.history_from_segments(histories[-1][1].segments)
            processes[node].kill()  # SIGKILL: no shutdown, no last words
            processes[node].wait()
            t_kill = now()
            out = {"node": node, "seed": seed, "history_before": len(before)}
            # Without the node: the running attempt ends (the planner gone: the arm stops).
            wait("the running plan's report", lambda: len(dock_reports()) >= killed_during)
            t_report, msg = dock_reports()[-1]
            report = convert.report_from_msg(msg)
            if node == "planner":
                out["stop_s"] = t_report - t_kill
                out["stop_detail"] = report.detail
                out["producer_lost"] = report.producer_lost
            t_respawn = now()
            bringup.respawn(processes, node, arguments, log_dir)
            wait("the next plan", lambda: len(record.plans) > killed_during)
            t_plan = now()
            expected = sum(len(r.segments) for _, r in dock_reports())
            plan = record.plans[-1]
            after = [convert.history_from_segments(m.segments) for t, m in histories if t > t_kill]
            out |= {
                "history_after": int(plan.history_length),
                "history_expected": expected,
                "history_kept": all(_starts_with(h, before) for h in after),
                "same_episode": plan.episode == episode_id,
                "next_plan_id": int(plan.plan_id),
                "resume_s": t_plan - t_respawn,
            }
            if node == "planner":
                out["stopped"] = all(_zero(m) for t, m in commands if t_report <= t <= t_respawn)
            else:  # only a restarted node restores one: the first start has no saved posterior
                log = (log_dir / "inference.log").read_text(errors="replace")
                out["warm_start_restored"] = "warm start restored" in log
            return out
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.shutdown(context=context)


def _zero(twist) -> bool:
    v = twist.twist.linear
    return (v.x, v.y, v.z) == (0.0, 0.0, 0.0)


def _starts_with(history, prefix) -> bool:
    k = len(prefix)
    return (
        len(history) >= k
        and np.array_equal(history.a[:k], prefix.a)
        and np.array_equal(history.b[:k], prefix.b)
        and np.array_equal(history.status[:k], prefix.status)
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--node", nargs="+", default=list(NODES), choices=NODES)
    parser.add_argument("--repeat", type=int, default=1, help="runs per node")
    parser.add_argument("--seed", type=int, default=5, help="mock terrain (5: several cycles)")
    parser.add_argument("--json", type=Path, default=None, help="write the runs here")
    args = parser.parse_args(argv)
    from tactile_dock_ros.tools import bringup

    bringup.isolate_dds(keep_domain=True)
    runs = []
    for node in args.node:
        for i in range(args.repeat):
            log_dir = Path(tempfile.mkdtemp(prefix=f"restart_{node}_{i}_"))
            try:
                runs.append(run(node, log_dir, args.seed))
            except (RuntimeError, TimeoutError) as err:  # a failed run is a row, not the end
                runs.append({"node": node, "seed": args.seed, "error": str(err)})
            print(json.dumps(runs[-1]))
    if args.json is not None:
        args.json.write_text(json.dumps(runs, indent=1))
    ok = all(
        "error" not in r
        and r["history_kept"]
        and r["same_episode"]
        and r["history_after"] == r["history_expected"]
        for r in runs
    )
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
