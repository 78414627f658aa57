"""The episode's posterior against a reference: HMC samples of each cycle of one docking
episode beside a reference posterior of the same history, ``--references`` independent runs
pooled: ``--reference smc`` (default; ``core.reference``: tempered SMC with elliptical slice
moves, nothing shared with the HMC seeding) or ``--reference rejection`` (prior draws that
satisfy the history: exact i.i.d. posterior draws, for short histories only - a cycle whose
runs accept fewer than ``--particles`` of ``--rejection-draws`` prior draws is skipped and
reported as such).

Per cycle: the largest and median standardized error of the HMC vertex means (in reference
standard deviations; beside it the same statistic for as many pooled reference draws, the
noise floor of independent draws, and the largest one between the reference runs' means, the
reference's own noise), all against the reference draws on which the recorded slides could
have happened (the loop's samples are conditioned on them; a cycle whose slides leave fewer
than two sets of its sample count is skipped), the share of samples a recorded slide leaves
(``slides``), how often the cycle's plan docks on the HMC samples and on the reference ones,
and what the planner decides on sample sets of the same size drawn from the reference
(give-ups, P_dock): whether the episode continues or gives up because of the posterior or
because of the sampler.

``--sampler-runs K`` adds K more runs of each checked cycle by ``--sampler-method`` (default
hmc; independent seeds; ``--sampler-start warm``: from the previous cycle's samples as the loop
does, ``cold``: from the sampler's own seeding): the max error of each run alone, and of the K
runs pooled (max, median, spread ratio) against the pooled reference and each reference run
(every reference draw: these runs sample the history's rows, not the slides).
Decision: a sampler's bias is what stays when pooling removes its noise; it is shown only if
the pooled runs lie farther from the reference runs than those lie from each other
(``reference_runs_mean_error_max``), the reference's own resolution.

Example: ``python -m tactile_dock_ros.tools.bench posterior --problem three_ledges --instance
19 --prior generic --cycles 3 5 7 --json out.json``. Two runs of 1000 particles took 5-14 min per
cycle on three_ledges (37-115 rows; the constraint evaluations of the elliptical slice moves);
``--quick`` runs 2 cycles with 200 particles. ``--repeats`` is not used. ``--prior depth`` (the
default) checks the sampler on the robot's prior (perception's ``prior_source: depth``: the
image conditioned on the terrain class library): its posteriors are narrow, so ``--reference
rejection`` reaches several cycles; ``--prior generic`` on the generic depth prior of the same
image.
"""

from __future__ import annotations

import time

import numpy as np

from tactile_dock_ros.core import explore, planner, problems, reference, sampling, simulate, slides
from tactile_dock_ros.perception.config import PerceptionConfig
from tactile_dock_ros.perception.prior_select import PRIOR_SOURCES, prior_source
from tactile_dock_ros.tools import package_files
from tactile_dock_ros.tools.bench.docking import (
    MODES,
    _at_least,
    _problem,
    _truths,
    add_episode_arguments,
    add_give_up_samples_argument,
    add_library_arguments,
    add_slide_argument,
    episode_seed,
    load_library,
)
from tactile_dock_ros.tools.bench.splits import SPLITS


def add_replay_arguments(parser, instance: int, seed: int) -> None:
    """The episode a suite replays (``replay_episode``): one of bench docking's truths (default
    ``instance``; ``--split`` and ``--seed`` as bench docking draws them) and episode seeds
    (default ``seed``), prior, mode, strategy, cycle cap, samples and the episode settings;
    shared with ``bench threads``.

    Decision: ``--split`` defaults to ``train`` here, unlike bench docking: these suites
    diagnose and compare code on the truths it may be tuned on, and their documented runs use
    them; ``--split test`` replays an episode of a held-out figure (one that failed, say)."""
    parser.add_argument("--problem", default="three_ledges", choices=problems.names())
    parser.add_argument(
        "--instance", type=_at_least(0), default=instance, help="truth index, as in bench docking"
    )
    parser.add_argument(
        "--split",
        choices=SPLITS,
        default="train",
        help="whose truths, drawn with --seed as bench docking draws them: train (the default, "
        "the truths the code may be tuned on) or test (held out: replay an episode of a bench "
        "docking figure)",
    )
    parser.add_argument(
        "--prior",
        type=prior_source,
        default="depth",
        choices=PRIOR_SOURCES,
        help="problem: the hand-made prior; depth: the mock camera's image conditioned on the "
        "terrain class library (--terrain-classes; the generic depth prior where the gate sends "
        "the image); generic: the generic depth prior of the same image (learned: the earlier "
        "name of depth)",
    )
    add_library_arguments(parser)
    parser.add_argument("--mode", default="compliant", choices=MODES)
    parser.add_argument("--strategy", default="ours", choices=explore.STRATEGIES)
    parser.add_argument(
        "--episode-seed",
        type=_at_least(0),
        default=seed,
        help="which of bench docking's --episode-seeds episodes (0: the truth's own seed)",
    )
    parser.add_argument("--max-cycles", type=_at_least(1), default=12, help="cycle cap")
    parser.add_argument("--samples", type=_at_least(2), default=100, help="posterior samples")
    add_episode_arguments(parser)
    add_give_up_samples_argument(parser)
    add_slide_argument(parser)


def replay_episode(args, max_cycles: int):
    """The truth (``docking._truths``' entry), the prior, the ``explore.CycleView`` of every
    cycle and the result of the episode ``add_replay_arguments`` chose, capped at
    ``max_cycles``."""
    config, library = None, None
    if args.prior != "problem":
        config = PerceptionConfig.load(package_files.resolve(args.perception_config))
    if args.prior == "depth":
        library = load_library(args)[0]
    generic_config = config if args.prior == "generic" else None
    truths = _truths(
        args, args.problem, args.instance + 1, generic_config, args.split, library, config
    )
    truth = truths[args.instance]
    problem = _problem(args.problem)
    shape = problem.prior if args.prior == "problem" else truth[args.prior]
    if shape is None:
        error = truth.get("perception_error", truth.get("generic_perception_error"))
        raise SystemExit(f"no {args.prior} prior for this truth: {error}")
    views: list[explore.CycleView] = []
    result = explore.run_episode(
        problem,
        truth["truth"],
        args.strategy,
        np.random.default_rng(episode_seed(truth["seed"], args.episode_seed)),
        max_cycles,
        n_samples=args.samples,
        give_up_threshold=args.give_up_threshold,
        give_up_samples=args.give_up_samples,
        compliant=args.mode == "compliant",
        slide_on_slip=args.slide_on_slip,
        prior=shape,
        observe=views.append,
    )
    return truth, shape, views, result


def add_arguments(parser) -> None:
    add_replay_arguments(parser, instance=19, seed=0)
    parser.add_argument(
        "--cycles", type=int, nargs="+", help="cycles to check, from 0 (default: all)"
    )
    parser.add_argument(
        "--particles", type=_at_least(100), default=1000, help="reference draws per run and cycle"
    )
    parser.add_argument(
        "--references",
        type=_at_least(2),
        default=2,
        help="independent reference runs per cycle, pooled (their spread is its own noise)",
    )
    parser.add_argument(
        "--reference",
        default="smc",
        choices=("smc", "rejection"),
        help="reference posterior: tempered SMC, or rejection (exact; short histories only)",
    )
    parser.add_argument(
        "--rejection-draws",
        type=_at_least(1000),
        default=2_000_000,
        help="prior draws per rejection reference run at most (a cycle whose runs accept "
        "fewer than --particles is skipped)",
    )
    parser.add_argument(
        "--sampler-runs",
        type=_at_least(0),
        default=0,
        help="more sampler runs per checked cycle, each alone and pooled against the references",
    )
    parser.add_argument(
        "--sampler-method", default="hmc", choices=sampling.MCMC_METHODS, help="of --sampler-runs"
    )
    parser.add_argument(
        "--sampler-start",
        default="warm",
        choices=("warm", "cold"),
        help="--sampler-runs from the previous cycle's samples (as the loop) or the seeding",
    )
    parser.add_argument("--quick", action="store_true", help="smoke run: 2 cycles, 200 particles")


def _mean_errors(samples: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """|mean(samples) - mean(ref)| per vertex coordinate, in reference standard deviations."""
    x, r = samples.reshape(len(samples), -1), ref.reshape(len(ref), -1)
    spread = r.std(axis=0)
    moving = spread > 0
    return np.abs(x.mean(axis=0) - r.mean(axis=0))[moving] / spread[moving]


def _slide_consistent(view: explore.CycleView, shape, samples: np.ndarray) -> np.ndarray:
    """Mask of the samples on which the cycle's recorded slides could have happened."""
    state, config = view.state, view.config
    return slides.consistent_with_slides(
        samples, shape.closed, state.history, state.move_ids, config.load, shape.friction,
        state.ignored,
    )  # fmt: skip


def _plan_docks(view: explore.CycleView, shape, samples: np.ndarray) -> float | None:
    """Share of ``samples`` on which the cycle's plan docks; None for a give-up (no path) or
    when no sample is left."""
    if view.plan.decision != "dock" or not len(samples):
        return None
    config = view.config
    docks = simulate.dock_outcomes(
        samples, shape.closed, view.plan.path, shape.friction, config.load, config.compliant
    )
    return float(docks.mean())


def _planned_count(view: explore.CycleView, n_samples: int) -> int:
    """The cycle's sample count as the loop asked for it: ``n_samples``, fewer when the slides
    left fewer (a give-up's draw-on returns more, up to 3000: ``episode_posterior.draw``)."""
    return min(len(view.samples), n_samples)


def _repeats(
    view: explore.CycleView, shape, warm_start, runs: int, method: str, rng, n_samples: int = 100
) -> list[sampling.PosteriorSamples]:
    """``runs`` more ``method`` runs of the cycle's history (``_planned_count`` draws each), from
    ``warm_start`` (the previous cycle's samples as ``explore`` uses them; None: the sampler's
    seeding)."""
    state = view.state
    return [
        sampling.sample_posterior(
            shape, state.history, _planned_count(view, n_samples), rng, method, init_z=warm_start,
            known_dropped=state.ignored,  # the rows the cycle's posterior left out
        )
        for _ in range(runs)
    ]  # fmt: skip


def _repeat_errors(
    runs: list[sampling.PosteriorSamples], each: list[np.ndarray], ref_v: np.ndarray
) -> dict:
    """Scores of more sampler runs against the pooled reference ``ref_v`` and each reference run of
    ``each``: every run alone (with whether it warned and how it re-seeded), and all pooled."""
    repeats = [run.vertices for run in runs]
    pooled = np.concatenate(repeats)
    errors = _mean_errors(pooled, ref_v)
    pooled_std = pooled.reshape(len(pooled), -1).std(axis=0)
    ref_std = ref_v.reshape(len(ref_v), -1).std(axis=0)
    moving = ref_std > 0
    return {
        "runs": len(repeats),
        "mean_error_max_each": [float(_mean_errors(run, ref_v).max()) for run in repeats],
        "warned_each": [not run.convergence.converged for run in runs],
        "reseeded_each": [run.convergence.reseeded for run in runs],
        "mass_rounds_each": [run.convergence.mass_rounds for run in runs],
        "pooled_mean_error_max": float(errors.max()),
        "pooled_mean_error_median": float(np.median(errors)),
        "pooled_std_ratio_median": float(np.median(pooled_std[moving] / ref_std[moving])),
        "pooled_to_reference_runs": [float(_mean_errors(pooled, ref).max()) for ref in each],
    }


class TooFewAccepted(Exception):
    """A rejection reference run accepted fewer prior draws than the particles asked for."""


def rejection_reference(
    shape, history, particles: int, rng, max_draws: int
) -> reference.ReferencePosterior:
    """``particles`` exact posterior draws: prior draws that satisfy every row of ``history``
    (``sampling``'s rejection method, at most ``max_draws`` tried), as a ReferencePosterior
    (log evidence: the log acceptance rate; no tempering stages). Raises TooFewAccepted when
    fewer are accepted: the history is too unlikely under the prior for an exact reference."""
    post = sampling.sample_posterior(
        shape, history, particles, rng, "rejection", max_draws=max_draws
    )
    if len(post.z) < particles:
        raise TooFewAccepted(
            f"rejection accepted {len(post.z)} of {post.info['draws']} prior draws, fewer than "
            f"the {particles} particles asked for (too long a history for --reference rejection)"
        )
    acceptance = post.info.get("acceptance", 1.0)  # an empty history accepts every draw
    return reference.ReferencePosterior(post.z, float(np.log(acceptance)), 0)


def compare(
    view: explore.CycleView,
    shape,
    particles: int,
    runs: int,
    rng,
    repeats=(),
    rejection_draws: int | None = None,
    n_samples: int = 100,
) -> dict:
    """One cycle: its HMC samples against ``runs`` reference runs of the same (kept) history,
    pooled; how far the runs' means lie apart says how far the reference itself can be
    trusted (at late depth-prior cycles two 1000-particle SMC runs differed by up to 0.7 std
    in a vertex mean: far more than independent draws would). The runs are SMC, or with
    ``rejection_draws`` ``rejection_reference`` runs (raises TooFewAccepted). ``repeats``:
    more sampler runs (``_repeats``), scored alone and pooled. The iid floor and the reference
    plans use sets of the cycle's sample count (``_planned_count``).

    Decision: the cycle's samples are the loop's posterior, conditioned on the recorded slides
    too (``episode_posterior.draw``), so they are set beside the reference draws the slides
    leave, and so are the noise floor, the runs' spread and the reference plans; the repeats
    sample the rows alone and are set beside every reference draw. Before, both were scored
    against every draw: on sloper train truth 1 (depth prior, non-compliant, whose slip slides
    on) the slides leave 2 % of cycle 1's exact draws, and a sampler that was right read 1.79
    std off. Raises TooFewAccepted when the slides leave fewer than two sets of the cycle's
    sample count, or fewer than two of a run."""
    state = view.state
    kept = np.setdiff1d(np.arange(len(state.history)), state.ignored)
    start = time.perf_counter()
    history = state.history.subset(kept)
    if rejection_draws is None:
        refs = [reference.smc_posterior(shape, history, particles, rng) for _ in range(runs)]
    else:
        refs = [
            rejection_reference(shape, history, particles, rng, rejection_draws)
            for _ in range(runs)
        ]
    seconds = time.perf_counter() - start
    each_drawn = [shape.vertices(r.z) for r in refs]  # the rows' posterior
    run_keeps = [_slide_consistent(view, shape, v) for v in each_drawn]
    each = [v[keep] for v, keep in zip(each_drawn, run_keeps, strict=True)]  # and the slides'
    ref_v = np.concatenate(each)
    n = _planned_count(view, n_samples)
    if len(ref_v) < 2 * n or min(len(v) for v in each) < 2:  # a run's spread needs two
        raise TooFewAccepted(
            f"the recorded slides leave {[len(v) for v in each]} of {particles} draws per "
            f"reference run, fewer than two sets of the cycle's {n} samples in all"
        )
    floor = _mean_errors(ref_v[:n], ref_v[n:])
    apart = max(
        float(_mean_errors(each[i], each[j]).max()) for i in range(runs) for j in range(i + 1, runs)
    )
    errors = _mean_errors(view.samples, ref_v)
    hmc_keep = _slide_consistent(view, shape, view.samples)
    ref_keep = np.concatenate(run_keeps)
    decisions = [
        planner.plan(ref_v[k : k + n], shape, state, view.config)
        for k in range(0, len(ref_v) - n + 1, n)
    ]
    row = {
        "cycle": view.cycle,
        "history_rows": len(kept),
        "dropped_rows": len(state.dropped),
        "deferred_rows": len(state.deferred),
        "reference_seconds": seconds,
        "reference_stages": [r.stages for r in refs],
        "log_evidence": [r.log_evidence for r in refs],
        "mean_error_max": float(errors.max()),
        "mean_error_median": float(np.median(errors)),
        "iid_mean_error_max": float(floor.max()),
        "reference_runs_mean_error_max": apart,
        "slide_consistent": {
            "hmc": float(hmc_keep.mean()),
            "reference": float(ref_keep.mean()),
            "reference_runs": [float(k.mean()) for k in run_keeps],
        },
        "plan": view.plan.decision,
        "plan_p_dock": view.plan.p_dock,
        "plan_docks_on": {
            "hmc": _plan_docks(view, shape, view.samples[hmc_keep]),
            "reference": _plan_docks(view, shape, ref_v),
        },
        "reference_plans": {
            "give_up": sum(d.decision == "give_up" for d in decisions),
            "of": len(decisions),
            "p_dock_median": float(np.median([d.p_dock for d in decisions])),
        },
    }
    if repeats:
        row["sampler_runs"] = _repeat_errors(repeats, each_drawn, np.concatenate(each_drawn))
    return row


HEADER = (
    f"{'cycle':>5} {'rows':>4} {'ref s':>6} {'logP(H)':>7} {'err max':>7} {'iid':>5} "
    f"{'runs':>5} {'med':>5} {'slide-ok hmc/ref':>16} {'plan P_dock':>11} {'docks hmc/ref':>13} "
    f"{'ref plans: give-ups, med P_dock':>31}"
)


def _share(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}"


def _line(row: dict) -> str:
    ok, docks, plans = row["slide_consistent"], row["plan_docks_on"], row["reference_plans"]
    return (
        f"{row['cycle']:>5} {row['history_rows']:>4} {row['reference_seconds']:>6.0f} "
        f"{np.mean(row['log_evidence']):>7.1f} {row['mean_error_max']:>7.2f} "
        f"{row['iid_mean_error_max']:>5.2f} {row['reference_runs_mean_error_max']:>5.2f} "
        f"{row['mean_error_median']:>5.2f} "
        f"{ok['hmc']:>7.2f}/{ok['reference']:<8.2f} {row['plan_p_dock']:>11.3f} "
        f"{_share(docks['hmc']):>6}/{_share(docks['reference']):<6} "
        f"{plans['give_up']:>14}/{plans['of']:<3} {plans['p_dock_median']:>12.3f}"
    )


def _repeat_line(row: dict) -> str:
    runs = row["sampler_runs"]
    each = runs["mean_error_max_each"]
    warned = runs["warned_each"]
    off = [w for e, w in zip(each, warned, strict=True) if e > 1.0]
    to_refs = " ".join(f"{e:.2f}" for e in runs["pooled_to_reference_runs"])
    return (
        f"      {runs['runs']} more sampler runs: max err each {min(each):.2f}-{max(each):.2f} "
        f"(median {np.median(each):.2f}; {len(off)} > 1, {sum(off)} of them warned; "
        f"{sum(warned)} warned, {sum(r > 0 for r in runs['reseeded_each'])} re-seeded, "
        f"{sum(r > 0 for r in runs['mass_rounds_each'])} by posterior mass); "
        f"pooled max {runs['pooled_mean_error_max']:.2f} median "
        f"{runs['pooled_mean_error_median']:.2f} std ratio {runs['pooled_std_ratio_median']:.2f}, "
        f"to each reference run {to_refs} (runs apart {row['reference_runs_mean_error_max']:.2f})"
    )


def run(args) -> dict:
    max_cycles, particles = (2, 200) if args.quick else (args.max_cycles, args.particles)
    if args.references * particles < 2 * args.samples:
        raise SystemExit(
            f"--references x --particles ({args.references} x {particles}) must be at least "
            f"2 x --samples ({args.samples}): the noise floor compares that many draws"
        )
    truth, shape, views, result = replay_episode(args, max_cycles)
    p_dock = [round(c.plan.p_dock, 3) for c in result.cycles_log]
    print(f"episode: {result.outcome} after {result.cycles} moves, P_dock per cycle {p_dock}")
    wanted = range(len(views)) if args.cycles is None else args.cycles
    if args.quick:
        wanted = list(wanted)[:2]
    unknown = sorted(set(wanted) - set(range(len(views))))
    if unknown:
        raise SystemExit(f"cycles {unknown} not in this episode (0..{len(views) - 1})")
    rejection_draws = args.rejection_draws if args.reference == "rejection" else None
    print(HEADER)
    rows = []
    for cycle in wanted:
        state = views[cycle].state
        rows_now = len(state.history) - len(state.ignored)  # kept rows, as ``compare`` counts
        print(
            f"  cycle {cycle}: {args.references} {args.reference} runs of {particles} draws, "
            f"{rows_now} rows ...",
            flush=True,
        )
        rng = np.random.default_rng([args.seed, cycle, 7])
        warm = views[cycle - 1].state.warm_start if cycle and args.sampler_start == "warm" else None
        repeat_rng = np.random.default_rng([args.seed, cycle, 8])  # references: the same without
        repeats = _repeats(
            views[cycle], shape, warm, args.sampler_runs, args.sampler_method, repeat_rng,
            args.samples,
        )  # fmt: skip
        try:
            rows.append(
                compare(
                    views[cycle],
                    shape,
                    particles,
                    args.references,
                    rng,
                    repeats,
                    rejection_draws,
                    args.samples,
                )
            )
        except TooFewAccepted as err:
            rows.append({"cycle": cycle, "history_rows": rows_now, "skipped": str(err)})
            print(f"  cycle {cycle} skipped: {err}")
            continue
        print(_line(rows[-1]), flush=True)
        if repeats:
            print(_repeat_line(rows[-1]), flush=True)
    return {
        "problem": args.problem,
        "instance": args.instance,
        "split": args.split,
        "prior": args.prior,
        # learned: which model perception chose (the class, or the generic fallback)
        "learned_model": truth.get("learned_model"),
        "learned_class": truth.get("learned_class"),
        "mode": args.mode,
        "strategy": args.strategy,
        "feasible": truth["feasible"][args.mode],
        "outcome": result.outcome,
        "p_dock": [c.plan.p_dock for c in result.cycles_log],
        "rhat": [c.convergence.rhat for c in result.cycles_log],
        "reference": args.reference,
        "particles": particles,
        "references": args.references,
        "samples": args.samples,
        "sampler_runs": {
            "runs": args.sampler_runs,
            "method": args.sampler_method,
            "start": args.sampler_start,
        },
        "cycles": rows,
    }
