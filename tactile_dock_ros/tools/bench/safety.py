"""The executor under faults on the mock arm over DDS.

executor and mock_hardware run as processes from the mock launch file on a flat floor
(``tools.safety``); the bench plays the planner and records every command to the arm.

* dropout: ``--dropouts`` times, while a plan moves, the mock stops its wrench or its pose
  stream (alternating; seeded random delay after the arm starts moving). Latency = stamp of
  the first zero command minus (stamp of the stream's last sample + ``sensor_timeout``),
  p50/p99/max; the requirement is 2 control periods.
* envelope: the refusal scenarios (target outside the box, absurd speed, force threshold
  above the limit, NaN/inf, plans of superseded/ended episodes), a 60 N force fault while
  moving, two plans at once; every command checked against the box, speed and force limits.
* exit: ``--exits`` times each, while a plan moves at 0.2 m/s, the executor process gets
  SIGKILL (nothing can stop the arm but the mock's own ``command_timeout``) or SIGTERM (the
  executor commands zero as it exits): the distance the tool moves from the signal until at
  rest (median/max), whether a zero command came.
* load: one 0.7 m plan at 0.2 m/s; baseline (sensors at the mock's rate, no other plans) vs
  loaded (each sensor sample republished 10 times, bursts of 10 plans every 0.25 s): the
  intervals between consecutive command stamps and their jitter |interval - period|,
  p50/p99 per repetition, medians over ``--repeats``, loaded / baseline ratios.

``--cpu-burners N`` runs every part beside N busy processes the bench starts (and ends with
the part; each stops by itself after ``BURNER_CAP_S`` at the latest): the machine under CPU
load, its load average reported per part. ``--thread-priority P [P ...]`` runs the parts once
per value of the executor's thread_priority (0: the normal scheduler), side by side in one
JSON (``by_thread_priority``).
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import yaml

from tactile_dock_ros.tools import bringup, safety

PARTS = ("dropout", "envelope", "load", "exit")
FAST_DIAGNOSTICS = {"executor": {"diagnostics_period": 0.2}}
BURNER_CAP_S = 1800  # a CPU burner ends itself after this, should the bench die first
_BURN = "import time\nend = time.monotonic() + {cap}\nwhile time.monotonic() < end:\n    pass\n"


def add_arguments(parser) -> None:
    parser.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS))
    parser.add_argument("--dropouts", type=int, default=20, help="dropouts to measure")
    parser.add_argument("--amplify", type=int, default=10, help="sensor rate factor (load)")
    parser.add_argument("--burst", type=int, default=10, help="plans per burst (load)")
    parser.add_argument("--exits", type=int, default=5, help="executor exits per signal (exit)")
    parser.add_argument(
        "--command-timeout",
        type=float,
        help="the mock arm's command_timeout, s (exit; default: config/mock.yaml's)",
    )
    parser.add_argument("--log-dir", type=Path, help="node logs (default: a temporary dir)")
    parser.add_argument(
        "--cpu-burners",
        type=int,
        default=0,
        help="busy processes started beside each part (CPU load; 0: none)",
    )
    parser.add_argument(
        "--thread-priority",
        type=int,
        nargs="+",
        help="run once per value of the executor's thread_priority (0: normal scheduler; "
        "default: its own)",
    )


@contextlib.contextmanager
def cpu_burners(count: int):
    """``count`` processes that keep a core busy until the block ends (or BURNER_CAP_S)."""
    code = _BURN.format(cap=BURNER_CAP_S)
    procs = [subprocess.Popen([sys.executable, "-c", code]) for _ in range(count)]
    try:
        yield procs
    finally:
        for proc in procs:
            proc.kill()
            proc.wait()


def _executor_overrides(args) -> dict:
    executor = dict(FAST_DIAGNOSTICS["executor"])
    if args.priority is not None:
        executor["thread_priority"] = args.priority
    return {"executor": executor}


def _ms(stats: dict) -> dict:
    return {k: (v * 1e3 if k != "n" else v) for k, v in stats.items()}


def _dropout(args, log_dir: Path) -> dict:
    rng = np.random.default_rng(args.seed)
    rows = []
    with safety.mock_floor(log_dir / "dropout", _executor_overrides(args)) as (probe, env, _):
        for i in range(args.dropouts):
            stream = ("wrench", "pose")[i % 2]
            row = safety.dropout(probe, env, stream, float(rng.uniform(0.0, 0.3)))
            rows.append(row)
            latency = row["latency_s"]
            print(
                f"  dropout {i + 1:3d} {stream:<6} "
                f"{'-' if latency is None else f'{latency * 1e3:6.1f} ms'}  {row['outcome']}"
            )
    latencies = [r["latency_s"] for r in rows if r["latency_s"] is not None]
    summary = {
        "dropouts": len(rows),
        "never_moved": sum(r.get("error") == "the arm never moved" for r in rows),
        "no_samples": sum("no sample" in r.get("error", "") for r in rows),
        "stopped": len(latencies),
        "aborted": sum(r["outcome"] == "ABORTED" for r in rows if "error" not in r),
        "aborted_with_segments": sum(bool(r["segments"]) for r in rows),
        "moving_after_stop": sum(r["moving_after_stop"] for r in rows),
        "latency_ms": _ms(safety.percentiles(latencies)),
        "within_2_periods": sum(x <= 2 * env.control_period for x in latencies),
        "control_period_ms": env.control_period * 1e3,
        "sensor_timeout_s": env.sensor_timeout,
    }
    lat = summary["latency_ms"]
    print(
        f"dropout: {summary['stopped']}/{len(rows)} stopped, latency after the timeout "
        f"p50 {lat['p50']:.1f} ms, p99 {lat['p99']:.1f} ms, max {lat['max']:.1f} ms "
        f"({summary['within_2_periods']} within 2 periods = {2 * env.control_period * 1e3:.0f} ms)"
    )
    return {"rows": rows, "summary": summary}


def _envelope(args, log_dir: Path) -> dict:
    with safety.mock_floor(log_dir / "envelope", _executor_overrides(args)) as (probe, env, _):
        result = safety.envelope_scenarios(probe, env)
    for row in result["refusals"]:
        print(f"  {row['scenario']:<36} refused={row['refused']}  {row['detail']}")
    print(f"  {'force fault (60 N while moving)':<36} {result['force_fault']}")
    print(f"  {'two plans at once':<36} {result['two_plans']}")
    print(
        f"envelope: {result['commands']} commands ({result['moving_commands']} moving), "
        f"{len(result['violations'])} violations"
    )
    return result


def _load(args, log_dir: Path) -> dict:
    configs = {"baseline": (1, 0), "loaded": (args.amplify, args.burst)}
    runs = {name: [] for name in configs}
    for r in range(args.repeats):
        for name, (amplify, burst) in configs.items():
            bringup.isolate_dds()
            with safety.mock_floor(
                log_dir / f"load_{name}_{r}", _executor_overrides(args), False, amplify
            ) as (probe, env, processes):
                pid = processes["executor"].pid
                result = safety.control_jitter(probe, env, burst, executor_pid=pid)
            runs[name].append(result)
            j, i, ticks = result["jitter_s"], result["interval_s"], result["executor_ticks"]
            longest = ticks["max_interval_s"] or float("nan")
            print(
                f"  {name:<8} rep {r}: {result['outcome']}, {result['commands']} commands, "
                f"interval p50 {i['p50'] * 1e3:.2f} ms p99 {i['p99'] * 1e3:.2f} ms, jitter p50 "
                f"{j['p50'] * 1e3:.2f} ms p99 {j['p99'] * 1e3:.2f} ms; executor ticks "
                f"{ticks['ticks']}, late {ticks['late']}, longest {longest * 1e3:.1f} ms; received "
                f"{result['executor_rate_hz']['wrench']:.0f} Hz wrench, executor CPU "
                f"{result['executor_cpu_percent']:.0f}%"
            )

    def median(name, key, q):
        return float(np.median([run[key][q] for run in runs[name]])) * 1e3

    table = {}
    for key in ("interval_s", "jitter_s"):
        for q in ("p50", "p99", "max"):
            base, loaded = median("baseline", key, q), median("loaded", key, q)
            table[f"{key[:-2]}_{q}_ms"] = {
                "baseline": base,
                "loaded": loaded,
                "ratio": loaded / base if base > 0 else None,
            }
    rates = {
        name: float(np.median([run["executor_rate_hz"]["wrench"] for run in runs[name]]))
        for name in runs
    }
    cpu = {
        name: float(np.median([run["executor_cpu_percent"] for run in runs[name]])) for name in runs
    }
    print(f"{'load (medians)':<18} {'baseline':>9} {'loaded':>9} {'ratio':>6}")
    for key, row in table.items():
        ratio = "-" if row["ratio"] is None else f"{row['ratio']:.2f}"
        print(f"{key:<18} {row['baseline']:9.2f} {row['loaded']:9.2f} {ratio:>6}")
    print(
        f"executor wrench rate: baseline {rates['baseline']:.0f} Hz, "
        f"loaded {rates['loaded']:.0f} Hz; executor CPU baseline {cpu['baseline']:.0f}%, "
        f"loaded {cpu['loaded']:.0f}% of one core"
    )
    own = {}  # the executor's count of its ticks, over all repetitions
    for name in runs:
        ticks = [run["executor_ticks"] for run in runs[name]]
        total = sum(t["ticks"] for t in ticks)
        own[name] = {
            "ticks": total,
            "late_percent": 100.0 * sum(t["late"] for t in ticks) / max(total, 1),
            "longest_ms": max((t["max_interval_s"] or 0.0) for t in ticks) * 1e3,
        }
        print(
            f"executor's own ticks ({name}): {own[name]['late_percent']:.2f} % of {total} more "
            f"than 2 periods after the previous, longest interval {own[name]['longest_ms']:.1f} ms"
        )
    not_ended = {name: sum(run["outcome"] != "NO_CONTACT" for run in runs[name]) for name in runs}
    print(f"plans not run to their end (aborted or no report): {not_ended}")
    return {
        "runs": runs,
        "table": table,
        "plans_not_ended": not_ended,
        "executor_ticks": own,
        "executor_wrench_rate_hz": rates,
        "executor_cpu_percent": cpu,
    }


def _exit(args, log_dir: Path) -> dict:
    rng = np.random.default_rng(args.seed)
    overrides = _executor_overrides(args)
    if args.command_timeout is not None:
        overrides["mock_hardware"] = {"command_timeout": args.command_timeout}
    rows = []
    with safety.mock_floor(log_dir / "exit", overrides) as (probe, env, processes):
        for i in range(args.exits):
            for signum in (signal.SIGKILL, signal.SIGTERM):
                delay = float(rng.uniform(0.1, 0.4))
                row = safety.executor_exit(probe, env, processes, signum, delay)
                rows.append(row)
                distance = row["distance_m"]
                print(
                    f"  exit {i + 1:3d} {row['signal']:<7} "
                    f"{'-' if distance is None else f'{distance * 1e3:5.1f} mm'}  "
                    f"zero command {row.get('zero_command')}"
                )
                if not row.get("respawned", True):
                    raise RuntimeError(f"the executor did not come back after {row['signal']}")
    config = yaml.safe_load(safety.CONFIG.read_text())["mock_hardware"]["ros__parameters"]
    command_timeout = args.command_timeout or config.get("command_timeout")
    summary = {"mock_command_timeout_s": command_timeout}
    for name in ("SIGKILL", "SIGTERM"):
        mine = [r for r in rows if r["signal"] == name]
        distances = [r["distance_m"] * 1e3 for r in mine if r["distance_m"] is not None]
        summary[name] = {
            "exits": len(mine),
            "distance_mm": safety.percentiles(distances, qs=(50,)),
            "zero_command": sum(bool(r.get("zero_command")) for r in mine),
            "moving_after_zero": sum(r.get("moving_after_zero", 0) for r in mine),
        }
        d = summary[name]["distance_mm"]
        print(
            f"exit {name}: distance after the signal median {d['p50']:.1f} mm, max "
            f"{d['max']:.1f} mm ({d['n']} runs), zero command in {summary[name]['zero_command']}"
        )
    return {"rows": rows, "summary": summary}


def run(args) -> dict:
    if args.dropouts < 1:
        raise SystemExit("--dropouts must be >= 1")
    if not 0 <= args.cpu_burners <= 64:
        raise SystemExit("--cpu-burners must be in [0, 64]")
    priorities = args.thread_priority or [None]
    if any(p is not None and not 0 <= p <= 99 for p in priorities):
        raise SystemExit("--thread-priority values must be in [0, 99]")
    log_dir = args.log_dir or Path(tempfile.mkdtemp(prefix="bench_safety_"))
    runs = {}
    for priority in priorities:
        args.priority = priority
        name = "default" if priority is None else str(priority)
        if len(priorities) > 1:
            print(f"=== executor thread_priority {name}")
        runs[name] = _run_parts(args, log_dir / f"thread_priority_{name}")
    out = {"parts": args.parts, "log_dir": str(log_dir), "cpu_burners": args.cpu_burners}
    if len(priorities) == 1:
        return out | {"thread_priority": priorities[0]} | runs[name]
    return out | {"by_thread_priority": runs}


def _run_parts(args, log_dir: Path) -> dict:
    out = {"load_average": {}}
    parts = {"dropout": _dropout, "envelope": _envelope, "load": _load, "exit": _exit}
    for part in args.parts:
        bringup.isolate_dds()
        print(
            f"== {part}" + (f" beside {args.cpu_burners} CPU burners" if args.cpu_burners else "")
        )
        with cpu_burners(args.cpu_burners):
            out[part] = parts[part](args, log_dir)
            out["load_average"][part] = os.getloadavg()[0]
        print(f"{part}: load average (1 min) {out['load_average'][part]:.1f}")
    return out
