"""Docking episodes on the mock profile over DDS: wall time and per-cycle latency per stage.

Each repetition brings up the five nodes of the mock launch file as processes (a fresh DDS
domain), runs one episode on ``--problem`` with ground-truth seed ``seed + r`` and records the
outcome, the cycles, the episode wall time and the perception / inference / planning /
execution latencies. Medians over repetitions; the machine may be shared, say so with the numbers.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np

from tactile_dock_ros.tools import bringup


def add_arguments(parser) -> None:
    parser.add_argument("--problem", default="sloper", help="benchmark problem of the terrain")
    parser.add_argument("--prior-source", default="depth", choices=("depth", "problem"))
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds per episode")


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
    try:
        with bringup.running(arguments, Path(tempfile.mkdtemp(prefix="bench_episode_"))):
            record = client.run(executor, timeout, progress=lambda line: print("   ", line))
    finally:
        executor.shutdown()
        client.destroy_node()
        rclpy.shutdown(context=context)
    cycles = record.cycles()

    def stage(key):
        return [c[key] for c in cycles if c[key] is not None]

    return {
        "seed": seed,
        "state": record.state,
        "cycles": len(cycles),
        "wall_s": record.wall_seconds,
        "perception_s": record.perception_seconds,
        "inference_s": stage("inference_s"),
        "planning_s": stage("planning_s"),
        "execution_s": stage("execution_s"),
    }


def run(args) -> dict:
    episodes = []
    for r in range(args.repeats):
        bringup.isolate_dds()
        result = _one(args.problem, args.seed + r, args.prior_source, args.timeout)
        print(
            f"seed {result['seed']}: {result['state']} in {result['cycles']} cycles, "
            f"{result['wall_s']:.2f} s"
        )
        episodes.append(result)

    def median(key):
        values = [v for e in episodes for v in (e[key] if isinstance(e[key], list) else [e[key]])]
        values = [v for v in values if v is not None]
        return float(np.median(values)) if values else None

    summary = {
        key: median(key)
        for key in ("wall_s", "perception_s", "inference_s", "planning_s", "execution_s")
    }
    summary["docked"] = sum(e["state"] == "DOCKED" for e in episodes)
    summary["cycles_median"] = float(np.median([e["cycles"] for e in episodes]))
    print(f"{'median':<16} {'seconds':>9}")
    for key in ("wall_s", "perception_s", "inference_s", "planning_s", "execution_s"):
        value = summary[key]
        print(f"{key:<16} {'-' if value is None else f'{value:9.3f}':>9}")
    print(f"docked {summary['docked']}/{len(episodes)}, median cycles {summary['cycles_median']}")
    return {"problem": args.problem, "prior_source": args.prior_source, "episodes": episodes,
            "summary": summary}  # fmt: skip
