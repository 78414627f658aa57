"""Benchmarks that reproduce the paper's experiments; JSON out, medians over repetitions.

    python -m tactile_dock_ros.tools.bench SUITE [--json OUT] [--repeats R] [--seed S] [...]

Each suite is a module ``tactile_dock_ros.tools.bench.<suite>`` (or as ``MODULES`` says) with
``add_arguments(parser)`` and ``run(args) -> dict``; ``run`` prints a human-readable table as
it goes and returns the JSON-serializable results, which are written to ``--json`` (and always
include the command line, the machine and the software versions). BLAS runs single-threaded unless
OPENBLAS_NUM_THREADS is set.
"""

from __future__ import annotations

import os

# Benchmarks measure one core: multi-threaded BLAS on these small matrix products only adds
# contention (set before numpy is first imported; an explicit setting in the shell wins).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse
import importlib
import json
import platform
import sys
import time
from pathlib import Path

from . import splits

SUITES = {
    # suite name -> one-line description
    "docking": "Fig. 13: ours vs GW vs IG per problem, on the problem and the depth-camera prior",
    "episode": "mock-profile episodes over DDS per problem: outcomes (give-up vs budget), latency",
    "exits": "an episode's sampler calls with and without the exit search's pair certificates",
    "fuzz": "malformed messages on every subscription of every node: deaths, exceptions, history",
    "holds": "evaluate_hold on held-out depth priors: latency, ROC AUC of P_dock (feasible truths)",
    "perception": "640x480 depth -> slice -> prior: decode, slice, assembly, occlusion sampler",
    "posterior": "an episode's HMC posterior per cycle vs an SMC reference: means, P_dock, give-up",
    "prior": "depth prior calibration: 2-sigma coverage, NLL, energy score, old vs new model",
    "probsim": "P(C_e) accuracy (App. B) and P_dock speed per docking site vs Monte Carlo / scipy",
    "safety": "executor under faults over DDS: sensor dropout latency, envelope, load jitter",
    "sampling": "EST of rejection/MH/Gibbs/HMC posterior sampling (Fig. 9) and tmg-hmc",
    "threads": "an episode's sampler calls again with each sampler_threads count: seconds, ratio",
}

MODULES = {"fuzz": "tactile_dock_ros.tools.fuzz"}  # suites not in this package


def _environment() -> dict:
    import numpy
    import scipy

    return {
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "machine": platform.machine(),
        "processor": platform.processor() or platform.machine(),
        "time_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m tactile_dock_ros.tools.bench", description=__doc__.split("\n")[0]
    )
    sub = parser.add_subparsers(dest="suite", required=True, metavar="SUITE")
    modules = {}
    for name, help_text in SUITES.items():
        module = importlib.import_module(MODULES.get(name, f"tactile_dock_ros.tools.bench.{name}"))
        suite_parser = sub.add_parser(name, help=help_text, description=module.__doc__)
        suite_parser.add_argument("--json", type=Path, help="write the results to this file")
        suite_parser.add_argument("--repeats", type=int, default=3, help="repetitions (median)")
        suite_parser.add_argument("--seed", type=int, default=0, help="base random seed")
        module.add_arguments(suite_parser)
        modules[name] = module
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error("--repeats must be >= 1")
    if hasattr(args, "split") and not 0 <= args.seed < splits.MAX_SEED:
        parser.error(f"--seed must be in [0, {splits.MAX_SEED}) to keep the splits apart")
    try:
        results = modules[args.suite].run(args)
    except FileNotFoundError as err:  # an input file (package_files.resolve names the places)
        print(f"bench {args.suite}: {err}", file=sys.stderr)
        return 2
    report = {"suite": args.suite, "argv": sys.argv, "environment": _environment(), **results}
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=2, default=float))
        print(f"wrote {args.json}")
    return 0
