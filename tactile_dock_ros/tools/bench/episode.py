"""Docking episodes on the mock profile over DDS: outcomes and per-cycle latency per stage.

Each episode brings up the five nodes of the mock launch file as processes (a fresh DDS
domain) and runs one episode on a problem's ground truth of seed ``seed + k`` (k < ``--seeds``)
for every problem of ``--problems``. Recorded: the final state and why (a GIVE_UP decision of
the planner on the docking probability, a GIVE_UP for want of a path (``no_path``, counted with
the other endings), the planner's cycle budget, or something else), the cycles, whether the truth is
feasible (``simulate.feasible``, with ideal compliance and without: the mock profile plans
non-compliant, config/mock.yaml), the episode wall time and the perception / inference /
planning / execution latencies, and where the nodes' logs are (``log_dir``): an episode
that ends neither DOCKED nor GAVE_UP (ABORTED, or no final state within ``--timeout``) first
asks every node for its threads' stacks (``bringup.dump_stacks``), so a node that went silent
shows where it computed. Per problem: counts and medians over its episodes. The machine
may be shared: say so with the latencies. ``--repeats`` is not used (the seeds are the episodes).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

from tactile_dock_ros.core import planner, problems, simulate
from tactile_dock_ros.perception.prior_select import PRIOR_SOURCES, SOURCE_ALIASES
from tactile_dock_ros.tools import bringup

STAGES = ("wall_s", "perception_s", "inference_s", "planning_s", "execution_s")


def _positive(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def add_arguments(parser) -> None:
    parser.add_argument("--problems", nargs="+", default=problems.names(), choices=problems.names())
    parser.add_argument("--seeds", type=_positive, default=5, help="truth seeds per problem")
    parser.add_argument(
        "--prior-source",
        default="depth",
        choices=(*PRIOR_SOURCES, *SOURCE_ALIASES),
        help="perception's prior_source (launch argument): depth (the default: the launch file's "
        "terrain_classes conditioned on the depth image), generic (the generic depth prior of "
        "the same image) or problem (the problem's hand-made prior)",
    )
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds per episode")


NO_PATH_REASONS = (planner.NO_WAY_OUT, planner.NO_PREFIX)  # give-ups for want of a path


def ended_by(record) -> str:
    """'docked', 'planner' (its GIVE_UP decision: no site worth trying, e.g. no docking
    probability above the threshold), 'no_path' (a GIVE_UP for want of a path,
    ``NO_PATH_REASONS``: the tool stuck in the likely-obstacle region, no collision-free
    prefix), 'budget' (``max_cycles`` spent), 'no_shape' (inference found none) or the final
    state in lower case (aborted, none).

    Decision: only a give-up on the docking sites judges the terrain infeasible (Sec. III-B);
    a planner that finds no way to move gives up on feasible truths too (the node suite's
    "no way out" after a wedged retreat), so it is counted apart, with the other endings."""
    message = record.detail
    if record.state == "DOCKED":
        return "docked"
    if record.state != "GAVE_UP":
        return record.state.lower()
    if "cycle budget" in message:
        return "budget"
    if "no shape consistent" in message:
        return "no_shape"
    return "no_path" if any(reason in message for reason in NO_PATH_REASONS) else "planner"


def _one(problem: str, seed: int, prior_source: str, timeout: float) -> dict:
    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor

    from tactile_dock_ros.tools import episode

    arguments = {"profile": "mock", "problem": problem, "seed": str(seed),
                 "prior_source": prior_source}  # fmt: skip
    context = Context()
    rclpy.init(context=context)
    client = episode.EpisodeClient(context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(client)
    log_dir = Path(tempfile.mkdtemp(prefix="bench_episode_"))
    dumped = []
    try:
        with bringup.running(arguments, log_dir) as processes:
            record = client.run(executor, timeout, progress=lambda line: print("   ", line))
            if record.state not in ("DOCKED", "GAVE_UP"):
                dumped = bringup.dump_stacks(processes, log_dir)
                print(f"    {record.state}: node stacks dumped into {log_dir}/<node>.log: "
                      f"{', '.join(dumped) or 'none'}", flush=True)  # fmt: skip
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.shutdown(context=context)
    cycles = record.cycles()

    def stage(key):
        return [c[key] for c in cycles if c[key] is not None]

    spec = problems.get(problem)
    truth = spec.sample_ground_truth(np.random.default_rng(seed))  # as mock_hardware draws it
    return {
        "problem": problem,
        "seed": seed,
        "feasible": bool(simulate.feasible(spec, truth)),
        "feasible_non_compliant": bool(simulate.feasible(spec, truth, compliant=False)),
        "state": record.state,
        "ended_by": ended_by(record),
        "message": record.detail,
        "cycles": len(cycles),
        "p_dock": [c["p_dock"] for c in cycles],
        "wall_s": record.wall_seconds,
        "perception_s": record.perception_seconds,
        "inference_s": stage("inference_s"),
        "planning_s": stage("planning_s"),
        "execution_s": stage("execution_s"),
        "log_dir": str(log_dir),
        "stacks_dumped": dumped,
    }


def summary(episodes: list[dict]) -> dict:
    """Counts and medians over one problem's episodes."""
    infeasible = [e for e in episodes if not e["feasible"]]

    def median(key):
        values = [v for e in episodes for v in (e[key] if isinstance(e[key], list) else [e[key]])]
        values = [v for v in values if v is not None]
        return float(np.median(values)) if values else None

    given_up = [e["cycles"] for e in infeasible if e["ended_by"] == "planner"]
    return {
        "episodes": len(episodes),
        "feasible": sum(e["feasible"] for e in episodes),
        "docked_on_feasible": sum(e["feasible"] and e["state"] == "DOCKED" for e in episodes),
        "infeasible_planner_give_up": len(given_up),
        "infeasible_planner_give_up_cycles_median": float(np.median(given_up))
        if given_up
        else None,
        "infeasible_budget": sum(e["ended_by"] == "budget" for e in infeasible),
        "other": sum(e["ended_by"] not in ("docked", "planner", "budget") for e in episodes),
        "cycles_median": float(np.median([e["cycles"] for e in episodes])),
        **{key: median(key) for key in STAGES},
    }


def _fmt(value, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def run(args) -> dict:
    episodes = []
    for name in args.problems:
        for seed in range(args.seed, args.seed + args.seeds):
            bringup.isolate_dds()
            e = _one(name, seed, args.prior_source, args.timeout)
            print(
                f"{name} seed {seed} ({'feasible' if e['feasible'] else 'infeasible'}): "
                f"{e['state']} ({e['ended_by']}) in {e['cycles']} cycles, {e['wall_s']:.2f} s",
                flush=True,
            )
            print(f"{name} seed {seed}: {e['state']} ({e['ended_by']})", file=sys.stderr)
            episodes.append(e)
    summaries = {}
    print(
        f"{'problem':13} {'docked/feas':>11} {'inf: planner':>12} {'budget':>6} {'other':>5} "
        f"{'cycles':>6} {'wall s':>7} {'percep s':>8} {'infer s':>7} {'plan s':>6} {'exec s':>6}"
    )
    for name in args.problems:
        s = summaries[name] = summary([e for e in episodes if e["problem"] == name])
        print(
            f"{name:13} {s['docked_on_feasible']:>5}/{s['feasible']:<5} "
            f"{s['infeasible_planner_give_up']:>5}/{s['episodes'] - s['feasible']:<6} "
            f"{s['infeasible_budget']:>6} {s['other']:>5} {s['cycles_median']:>6.1f} "
            f"{_fmt(s['wall_s'], '.2f'):>7} {_fmt(s['perception_s'], '.3f'):>8} "
            f"{_fmt(s['inference_s'], '.3f'):>7} {_fmt(s['planning_s'], '.3f'):>6} "
            f"{_fmt(s['execution_s'], '.2f'):>6}"
        )
    return {"prior_source": args.prior_source, "seeds": args.seeds, "summary": summaries,
            "episodes": episodes}  # fmt: skip
