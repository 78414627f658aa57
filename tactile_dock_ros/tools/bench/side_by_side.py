"""Sampler settings side by side on one docking episode (``bench threads``, ``bench exits``).

The episode is bench docking's (a training truth unless ``--split test``, as ``bench
posterior``: ``--problem``, ``--instance``, ``--episode-seed``, ``--prior``, ``--mode``,
``--strategy``), run once with the default settings. Each cycle's sampler call is then repeated
with the inputs the loop gave it (the history, the previous posterior as warm start, the rows
left out and deferred) and its own seeded generator, once per setting and repetition; within a
repetition the settings run in rotating order, so that a drift of the machine's speed spreads
over all of them. Per cycle: the median seconds per setting and its ratio to the first
setting's. The settings change only how fast the sampler is: a cycle whose draws differ between
them fails the run. Cycles without a history (prior draws only) are not timed.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable

import numpy as np

from tactile_dock_ros.core import sampling
from tactile_dock_ros.tools.bench.posterior import add_replay_arguments, replay_episode


def add_arguments(parser) -> None:
    add_replay_arguments(parser, instance=9, seed=1)
    parser.add_argument("--quick", action="store_true", help="smoke run: 3 cycles, 1 repeat")


def _timed(shape, view, before, n_samples, seed, setting: Callable[[], dict]):
    """Seconds and draws of ``view``'s sampler call, as the loop made it after ``before``,
    under ``setting`` (it applies the setting and returns the call's extra arguments)."""
    extra = setting()
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
        **extra,
    )
    return time.perf_counter() - started, post.z


def compare(args, settings: dict[str, Callable[[], dict]], what: str) -> dict:
    """Every sampled cycle of ``args``' episode timed under each of ``settings`` (label ->
    a callable that applies the setting and returns ``sample_posterior``'s extra arguments;
    ratios are to the first); ``what`` names the settings in messages. Returns the per-cycle
    rows and the summary (summed and slowest median cycle per setting, their ratios)."""
    labels = list(settings)
    repeats = 1 if args.quick else args.repeats
    _, shape, views, result = replay_episode(args, 3 if args.quick else args.max_cycles)
    outcome = f"{result.outcome} after {result.cycles} cycles"
    print(f"episode: {outcome}; {what} {labels}, {repeats} repeat(s) per cycle")
    print(f"{'cycle':>5} {'rows':>5} " + " ".join(f"{f'{t} s':>12}" for t in labels) + "  ratio")
    cycles = []
    for before, view in itertools.pairwise(views):  # cycle k+1 sampled after cycle k's state
        seconds = {t: [] for t in labels}
        for rep in range(repeats):
            draws = []
            for t in labels[rep % len(labels) :] + labels[: rep % len(labels)]:
                s, z = _timed(
                    shape, view, before.state, args.samples, [args.seed, view.cycle, rep],
                    settings[t],
                )  # fmt: skip
                seconds[t].append(s)
                draws.append(z)
            if any(not np.array_equal(z, draws[0]) for z in draws[1:]):
                raise SystemExit(f"cycle {view.cycle}: the draws differ between {what}")
        median = {t: float(np.median(seconds[t])) for t in labels}
        row = {
            "cycle": view.cycle,
            "rows": len(view.state.history),
            "seconds": seconds,
            "median_seconds": median,
            "ratio_to_first": {t: median[t] / median[labels[0]] for t in labels},
        }
        cycles.append(row)
        print(
            f"{view.cycle:>5} {row['rows']:>5} "
            + " ".join(f"{median[t]:>12.3f}" for t in labels)
            + "  "
            + " ".join(f"{row['ratio_to_first'][t]:.2f}" for t in labels[1:])
        )
    totals = {t: sum(c["median_seconds"][t] for c in cycles) for t in labels}
    slowest = {t: max((c["median_seconds"][t] for c in cycles), default=0.0) for t in labels}
    first = labels[0]
    summary = {
        "total_seconds": totals,
        "slowest_cycle_seconds": slowest,
        "total_ratio_to_first": {t: totals[t] / totals[first] for t in totals} if cycles else {},
        "slowest_ratio_to_first": {t: slowest[t] / slowest[first] for t in slowest}
        if cycles
        else {},
    }
    for t in labels:
        print(f"{t}: summed median cycle {totals[t]:.2f} s, slowest {slowest[t]:.2f} s")
    return {
        "problem": args.problem,
        "instance": args.instance,
        "split": args.split,
        "prior": args.prior,
        "mode": args.mode,
        "strategy": args.strategy,
        "episode_seed": args.episode_seed,
        "episode": outcome,
        "repeats": repeats,
        "samples": args.samples,
        "cycles": cycles,
        "summary": summary,
        "note": "sampler wall time per cycle (sample_posterior only, not planning), median over "
        "repeats; the settings of a repeat run one after another in rotating order",
    }
