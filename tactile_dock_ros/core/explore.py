"""Bayesian tactile exploration loop (paper Sec. III-B) and the Sec. VI-A baselines.

Each cycle: infer (posterior samples given the history) -> plan -> execute the plan on the
ground-truth simulator -> add the observed segments to the history. The episode ends when the
tool docks, when the planner gives up (best P_dock below the threshold, or no site/path left),
after ``max_cycles`` cycles (``outcome == "cycle_cap"``, not a give-up), or on an error, which
is caught and reported (``outcome == "error"``, ``message``) so nothing escapes the loop.

Strategies share the estimator and the planner and differ in the planner's objective:
``ours`` = eq. (24); ``gw`` = growing window; ``ig`` = one greedy docking step then two
information-gain probes, repeating (cycle 1, 4, 7, ... greedy).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from . import episode_posterior, geometry2d, planner, simulate, slides
from .convergence import Convergence
from .episode import EpisodeState, PlannerConfig
from .history import History, Status
from .shape import GaussianShape

STRATEGIES = ("ours", "gw", "ig")


@dataclass(frozen=True)
class CycleLog:
    """One exploration cycle: what was planned, what happened, and how long it took."""

    cycle: int
    plan: planner.Plan
    samples: np.ndarray  # (k, n, 2) a few posterior samples, for plotting
    docked: bool
    contact: bool
    stop_point: np.ndarray  # (2,) NaN when nothing was executed
    inference_seconds: float
    planning_seconds: float
    dropped: int  # observations the sampler ignored as inconsistent
    rejected: int  # posterior draws on which a recorded slide could not have happened
    history_length: int  # observations available when this cycle planned
    convergence: Convergence  # the sampler's between-chain check of this cycle's samples
    deferred: int = 0  # observations the sampler left out while their seed search goes on


@dataclass(frozen=True)
class CycleView:
    """What one cycle planned on: the planner's exact inputs and its decision."""

    cycle: int
    state: EpisodeState  # its history, slides' move ids, dropped rows, tool, targets
    config: PlannerConfig  # with this cycle's objective
    plan: planner.Plan
    samples: np.ndarray  # (N, n, 2) all posterior samples of the cycle


@dataclass(frozen=True)
class EpisodeResult:
    """Outcome of ``run_episode``: ``outcome`` in docked | gave_up | cycle_cap | error."""

    docked: bool
    gave_up: bool
    cycles: int  # executed moves
    history: History
    cycles_log: list[CycleLog] = field(default_factory=list)
    outcome: str = "cycle_cap"
    message: str = ""


def _objective(strategy: str, cycle: int) -> str:
    if strategy == "ours":
        return "ours"
    if strategy == "gw":
        return "window"
    return "greedy" if cycle % 3 == 0 else "info_gain"


def run_episode(
    problem,
    ground_truth: np.ndarray,
    strategy: str = "ours",
    rng: np.random.Generator | None = None,
    max_cycles: int = 30,
    *,
    n_samples: int = 100,
    method: str = "hmc",
    give_up_threshold: float = 1e-3,
    compliant: bool = True,
    slide_on_slip: bool = False,
    keep_samples: int = 20,
    prior: GaussianShape | None = None,
    observe: Callable[[CycleView], None] | None = None,
    sampler_threads: int = 1,
    give_up_samples: int = 0,
) -> EpisodeResult:
    """Explore ``ground_truth`` (n, 2) of ``problem`` until docked, give-up or ``max_cycles``.

    ``rng`` drives every random choice (default: ``np.random.default_rng(0)``), so the same
    seed gives the same episode. The loop holds an ``episode.EpisodeState``: posterior chains
    are warm-started from the previous cycle's samples and each history row records its cycle
    (from 1), so the planner gets only samples on which every recorded compliant slide could
    have happened, topped up when the slides rule out most draws and, when no sample holds the
    load anywhere, to the draws a give-up needs (``episode_posterior.draw``); a later cycle's
    would-be give-up on fewer than ``give_up_samples`` samples draws on to that many and plans
    again (``episode_posterior.draw_on``; 0: off), as the planner node asks the inference node.
    ``prior`` replaces ``problem.prior`` as the robot's belief (e.g. one perceived from a depth
    image, ``perception.mock_camera.depth_prior``; the planner takes its friction); the truth
    is still simulated with the problem's load, friction, start and ``problem.prior.closed``.
    ``slide_on_slip`` (non-compliant episodes; the executor's ``slide_on_slip``): a slip at the
    first contact goes on as a slide of at most ``simulate.MAX_SLIDE_M`` that gives the
    evidence of a compliant slide but docks nowhere (``simulate.guarded_path``); the planner
    predicts as without it, so its P_dock is of the executed event.
    ``observe`` (diagnostic tools, e.g. ``tools.bench.posterior``) is called with a
    ``CycleView`` after each plan, before the move; an exception it raises ends the episode
    as an error like any other. ``sampler_threads``: ``sampling.sample_posterior``'s
    ``threads`` (the same episode in any count, only the cycle times change).
    Raises ValueError on a bad strategy, ``max_cycles``, ``give_up_samples`` or planner setting
    (``PlannerConfig``).
    """
    if int(give_up_samples) != give_up_samples or give_up_samples < 0:
        raise ValueError(f"give_up_samples must be an integer >= 0, got {give_up_samples}")
    if strategy not in STRATEGIES:
        raise ValueError(f"unknown strategy {strategy!r}; choose from {STRATEGIES}")
    if max_cycles < 1:
        raise ValueError(f"max_cycles must be >= 1, got {max_cycles}")
    rng = np.random.default_rng(0) if rng is None else rng
    prior = problem.prior if prior is None else prior
    config = PlannerConfig(
        problem.load, problem.contact_resolution, give_up_threshold, compliant=compliant
    )
    state = EpisodeState(tool=problem.start)
    log: list[CycleLog] = []
    try:
        for cycle in range(max_cycles):
            t0 = time.perf_counter()
            post = episode_posterior.draw(
                prior,
                state,
                n_samples,
                rng,
                config.load,
                method=method,
                threads=sampler_threads,
                hold_draws=planner.give_up_draws(give_up_threshold),
            )
            t1 = time.perf_counter()
            if len(post.vertices) < 2:
                return _finish(state, log, "error", f"inference returned {len(post.z)} samples")
            state = state.sampled(post.z, post.dropped, post.deferral)
            objective = _objective(strategy, cycle)
            config = dataclasses.replace(config, objective=objective)
            decision = planner.plan(post.vertices, prior, state, config)
            drawn_on = 0.0
            if _read_off_too_few(decision, state, post, give_up_samples):
                t_on = time.perf_counter()
                post = episode_posterior.draw_on(
                    prior, state, post, give_up_samples - len(post.z), rng, config.load,
                    method=method, threads=sampler_threads,
                )  # fmt: skip
                state = state.sampled(post.z, post.dropped, post.deferral)
                drawn_on = time.perf_counter() - t_on
                decision = planner.plan(post.vertices, prior, state, config)
            t2 = time.perf_counter()
            if observe is not None:
                observe(CycleView(cycle, state, config, decision, post.vertices))
            entry = dict(
                cycle=cycle,
                plan=decision,
                samples=post.vertices[:keep_samples],
                inference_seconds=t1 - t0 + drawn_on,
                planning_seconds=t2 - t1 - drawn_on,
                dropped=len(post.dropped),
                deferred=len(post.deferred),
                rejected=decision.rejected + post.info["slide_rejected"],
                history_length=len(state.history),
                convergence=post.convergence,
            )
            if decision.decision == "give_up":
                log.append(
                    CycleLog(**entry, docked=False, contact=False, stop_point=np.full(2, np.nan))
                )
                return _finish(state, log, "gave_up", decision.reason)
            run = simulate.guarded_path(
                ground_truth,
                problem.prior.closed,
                decision.path,
                problem.friction,
                problem.load,
                compliant,
                problem.contact_resolution,
                slide_on_slip=slide_on_slip and not compliant,
            )
            log.append(
                CycleLog(**entry, docked=run.docked, contact=run.contact, stop_point=run.stop_point)
            )
            evidence = run.observations
            if run.separated:
                evidence = slide_evidence(
                    ground_truth,
                    problem.prior.closed,
                    run,
                    problem.load,
                    problem.contact_resolution,
                )
            state = state.record(evidence, cycle + 1)
            tool = _backed_off(run, decision.path, problem.contact_resolution)
            state = state.aim(decision.target_point).move(tool)
            if run.docked:
                return _finish(state, log, "docked", f"docked at {np.round(run.stop_point, 4)}")
    except Exception as error:  # the loop reports every failure, never raises
        return _finish(state, log, "error", f"{type(error).__name__}: {error}")
    return _finish(state, log, "cycle_cap", f"no dock after {max_cycles} cycles")


def _read_off_too_few(decision, state: EpisodeState, post, give_up_samples: int) -> bool:
    """Whether a give-up came after an observation on fewer than ``give_up_samples`` samples
    (the first cycle counts prior draws instead: ``planner.first_cycle_draws``)."""
    return (
        decision.decision == "give_up" and len(state.history) > 0 and len(post.z) < give_up_samples
    )


def slide_evidence(
    ground_truth: np.ndarray,
    closed: bool,
    run: simulate.Execution,
    load,
    contact_resolution: float,
) -> History:
    """``run.observations`` plus what the compliant slide after the first contact showed.

    ``simulate.guarded_path`` records the first loading contact only (its stick/slip status).
    Under compliance (or ``slide_on_slip``, within ``max_slide``) a slipping tool then slides
    along the surface up to the vertex where it separates (Sec. V-A2, ``run.separated``),
    pushing along ``load`` and slipping all the way. The robot knows its
    trace, a polyline whose corners are where its direction changed; each straight piece
    between two corners (a surface edge crossed completely) gives slip observations every 4 cm
    (``slides.crossed_piece_evidence``). Without this the posterior only learns that the first
    contacted edge slips and keeps proposing the edges the tool already slid over
    (three_ledges: P_dock stayed near 0.5 for 30 cycles on infeasible truths), so the give-up
    test of Sec. III-B never fired.
    """
    obs = run.observations
    status = int(obs.status[-1]) if len(obs) else Status.FREE
    feature = run.stop_feature
    if status not in (Status.SLIP_LEFT, Status.SLIP_RIGHT) or feature is None:
        return obs
    if feature.kind != "vertex":
        return obs
    v = np.asarray(ground_truth, float)
    edges, _, _ = simulate.edge_index_arrays(len(v), closed)
    contact = 0.5 * (obs.a[-1] + obs.b[-1])
    push = geometry2d.unit(load, "load")
    half = 0.5 * contact_resolution * push
    hit, edge, _, _ = simulate.first_hits(
        v[None, edges[:, 0]], v[None, edges[:, 1]], contact - half, contact + half
    )
    if not hit[0]:
        return obs
    going_left = status == Status.SLIP_LEFT
    # edges crossed completely: between consecutive trace vertices
    crossed = simulate.slide_trace(len(v), closed, int(edge[0]), going_left, feature.index)
    pieces = slides.crossed_piece_evidence(
        v[crossed[:-1]], v[crossed[1:]], push, contact_resolution, status
    )
    return obs.extend(pieces.a, pieces.b, pieces.status)


def _backed_off(run, path: np.ndarray, contact_resolution: float) -> np.ndarray:
    """Where the tool rests after a move: backed off the contact along the last free segment."""
    obs = run.observations
    free = np.flatnonzero(obs.status == 0)
    if len(free):
        return np.asarray(obs.b[free[-1]], float)
    if run.contact:  # contact within the first resolution step: back up along the path
        direction = path[1] - path[0]
        return run.stop_point - contact_resolution * direction / np.linalg.norm(direction)
    return np.asarray(path[-1], float)


def _finish(state: EpisodeState, log, outcome: str, message: str) -> EpisodeResult:
    return EpisodeResult(
        docked=outcome == "docked",
        gave_up=outcome == "gave_up",
        cycles=sum(1 for c in log if c.plan.decision == "dock"),
        history=state.history,
        cycles_log=log,
        outcome=outcome,
        message=message,
    )
