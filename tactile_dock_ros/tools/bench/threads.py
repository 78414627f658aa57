"""Sampler threads side by side: every cycle of one docking episode sampled again with each
``--threads`` count (the inference node's ``sampler_threads``), ``--repeats`` times; per cycle
the median seconds per count and its ratio to the first count's. The draws must be the same in
every count: a cycle whose draws differ fails the run.

The episode is bench docking's (a training truth, as ``bench posterior``: ``--problem``,
``--instance``, ``--episode-seed``, ``--prior``, ``--mode``, ``--strategy``), run once with one
thread. Each cycle's sampler call is then repeated with the inputs the loop gave it (the
history, the previous posterior as warm start, the rows left out and deferred) and its own
seeded generator; within a repetition the counts run in rotating order, so that a drift of the
machine's speed spreads over all counts. Cycles without a history (prior draws only) are not
timed.

Example: ``python -m tactile_dock_ros.tools.bench threads --problem three_ledges --instance 9
--episode-seed 1 --threads 1 2 --repeats 5 --json out.json``. On a machine that runs other work,
counts above its free cores only add contention.
"""

from __future__ import annotations

import itertools
import time

import numpy as np

from tactile_dock_ros.core import sampling
from tactile_dock_ros.tools.bench.docking import _at_least
from tactile_dock_ros.tools.bench.posterior import add_replay_arguments, replay_episode


def add_arguments(parser) -> None:
    add_replay_arguments(parser, instance=9, seed=1)
    parser.add_argument(
        "--threads",
        type=_at_least(1),
        nargs="+",
        default=[1, 2],
        help="sampler thread counts, side by side (ratios are to the first)",
    )
    parser.add_argument("--quick", action="store_true", help="smoke run: 3 cycles, 1 repeat")


def _timed(shape, view, before, n_samples, threads, seed):
    """Seconds and draws of ``view``'s sampler call, as the loop made it after ``before``."""
    started = time.perf_counter()
    post = sampling.sample_posterior(
        shape,
        view.state.history,
        n_samples,
        np.random.default_rng(seed),
        init_z=before.warm_start,
        known_dropped=before.dropped,
        deferral=before.deferral,
        seed_round_restarts=sampling.SEED_ROUND_RESTARTS,
        threads=threads,
    )
    return time.perf_counter() - started, post.z


def run(args) -> dict:
    counts = list(dict.fromkeys(args.threads))
    repeats = 1 if args.quick else args.repeats
    _, shape, views, result = replay_episode(args, 3 if args.quick else args.max_cycles)
    outcome = f"{result.outcome} after {result.cycles} cycles"
    print(f"episode: {outcome}; threads {counts}, {repeats} repeat(s) per cycle")
    print(f"{'cycle':>5} {'rows':>5} " + " ".join(f"{f'{t} thr s':>9}" for t in counts) + "  ratio")
    cycles = []
    for before, view in itertools.pairwise(views):  # cycle k+1 sampled after cycle k's state
        seconds = {t: [] for t in counts}
        for rep in range(repeats):
            draws = []
            for t in np.roll(counts, -rep).tolist():
                s, z = _timed(
                    shape, view, before.state, args.samples, t, [args.seed, view.cycle, rep]
                )
                seconds[t].append(s)
                draws.append(z)
            if any(not np.array_equal(z, draws[0]) for z in draws[1:]):
                raise SystemExit(f"cycle {view.cycle}: the draws differ between thread counts")
        median = {t: float(np.median(seconds[t])) for t in counts}
        row = {
            "cycle": view.cycle,
            "rows": len(view.state.history),
            "seconds": {str(t): seconds[t] for t in counts},
            "median_seconds": {str(t): median[t] for t in counts},
            "ratio_to_first": {str(t): median[t] / median[counts[0]] for t in counts},
        }
        cycles.append(row)
        print(
            f"{view.cycle:>5} {row['rows']:>5} "
            + " ".join(f"{median[t]:>9.3f}" for t in counts)
            + "  "
            + " ".join(f"{row['ratio_to_first'][str(t)]:.2f}" for t in counts[1:])
        )
    totals = {str(t): sum(c["median_seconds"][str(t)] for c in cycles) for t in counts}
    slowest = {
        str(t): max((c["median_seconds"][str(t)] for c in cycles), default=0.0) for t in counts
    }
    first = str(counts[0])
    summary = {
        "total_seconds": totals,
        "slowest_cycle_seconds": slowest,
        "total_ratio_to_first": {t: totals[t] / totals[first] for t in totals} if cycles else {},
        "slowest_ratio_to_first": {t: slowest[t] / slowest[first] for t in slowest}
        if cycles
        else {},
    }
    for t in counts:
        print(
            f"{t} thread(s): summed median cycle {totals[str(t)]:.2f} s, "
            f"slowest {slowest[str(t)]:.2f} s"
        )
    return {
        "problem": args.problem,
        "instance": args.instance,
        "split": "train",
        "prior": args.prior,
        "mode": args.mode,
        "strategy": args.strategy,
        "episode_seed": args.episode_seed,
        "episode": outcome,
        "threads": counts,
        "repeats": repeats,
        "samples": args.samples,
        "cycles": cycles,
        "summary": summary,
        "note": "sampler wall time per cycle (sample_posterior only, not planning), median over "
        "repeats; the counts of a repeat run one after another in rotating order",
    }
