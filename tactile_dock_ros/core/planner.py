"""Docking planner (paper Sec. V-B): the best guarded move under the posterior, or give up.

A plan is a polyline whose last segment is the loading move: it travels along ``load`` (the
direction the robot pushes, the paper's -f_load) through the expected midpoint of a target edge
(the edge's *optimal terminal segment*). The prefix leaves the likely-obstacle region with
increasing clearance from the mean shape and reaches the tool through the unlikely-obstacle
region by a visibility-graph shortest path (``core.freespace``).

Objective (eq. 24): J = P_dock * B(min_p' |aim - aim'| / w), B(z) = 1 - exp(-z), where aim is
the terminal segment's target point (the expected edge midpoint), aim' those of earlier plans,
and w the contact resolution. P_dock comes from the probabilistic simulation
(``probsim``) under the moment-fit Gaussian of the posterior samples: candidates are ranked by
the terminal move's estimate (all edges in one batched call); the reported P_dock is
``probsim.dock_probability`` of the whole chosen path (which also multiplies in the probability
that the prefix touches nothing, close to 1 since it stays in the UOR). Both are capped per stop
feature by the samples' frequency of that feature holding the load (``capped_p_dock``): the
Gaussian fit does not encode the history's slip constraints, the samples do. The give-up test
(Sec. III-B: best P_dock below ``give_up_threshold``) uses the capped values.

Decision (the first cycle's give-up, ``first_cycle_draws``): the cap's resolution is 1/N, so
with the inference node's N = 100 samples a give-up below 0.001 reads "no sample holds", which
a hold of 1 % probability gives 37 % of the time. Before any observation the posterior is the
prior, whose exact draws are cheap: when the first cycle's best P_dock on the N samples is below
the threshold, the caps are recomputed over the samples plus prior draws up to
``ceil(3 / give_up_threshold)`` in all (at most ``PRIOR_DRAWS_MAX``; no hold in 3 / t draws
bounds P(hold) below t at 95 %, the rule of three), and a path that docks on none of the
samples is checked on the prior draws too. Only would-be give-ups pay; every other plan is the
one of the N samples (measured, ``bench holds``: recounting every first cycle over 3000 draws
put ``/evaluate_hold``'s p99 at 446-488 ms, would-be give-ups only at 91-93 ms; target 200 ms).
The draws come from a generator of fixed seed (``PRIOR_DRAWS_SEED``), so a replay of the
journaled samples plans the same. Later cycles' posteriors have no cheap exact draws: there the
sampler draws on when no sample lets an edge hold (``episode_posterior.draw``'s ``hold_draws``,
``give_up_draws`` of the threshold; the inference node's ``give_up_draws``) and the planner
plans on all the draws it gets; with the loops' ``give_up_samples`` a would-be give-up on fewer
samples is planned again on more (``episode_posterior.draw_on``).

Steps 1-5 of Sec. V-B, as implemented: (1) LOR from the samples; (2-4) the terminal segment and
its P_dock for every edge facing the load (an O(n) estimate each), then J; (5) prefixes are
planned lazily in order of decreasing J and the first that succeeds is optimal. This is the
paper's pruning taken to its end: an edge whose J (or P_dock) is below the best found so far is
never path-planned, and since edges are visited best-first no later edge can improve on the
first success. The paper visits edges by P(C_e, K_e); visiting by J itself needs no extra
estimate and plans at most as many prefixes.

Baselines (Sec. VI-A) share everything but the score: ``greedy`` = P_dock; ``window`` (GW) =
the untried site nearest the first site tried; ``info_gain`` (IG) = entropy of the predicted
stopping feature (decision documented in ``score``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import probsim, simulate, slides
from .episode import OBJECTIVES, EpisodeState, PlannerConfig
from .freespace import FreeSpace, likely_obstacle_region
from .history import History, Status
from .shape import GaussianShape

PRIOR_DRAWS_MAX = 3000  # a give-up's draws at most (``give_up_draws``)
PRIOR_DRAWS_SEED = 0  # the first cycle's prior draws: fixed, so a replay plans the same
# An edge faces the load when the push has at least this component against its outward normal.
_MIN_FACING = 0.05
# Longest search along a terminal segment's backward ray, in ray steps.
_MAX_RAY_STEPS = 400


@dataclass(frozen=True)
class Candidates:
    """Optimal terminal segment of every edge facing the load (arrays indexed like ``edges``).

    Attributes:
        edges: (C,) target edge indices.
        aim: (C, 2) expected edge midpoints, metres.
        start: (C, 2) where the loading move starts.
        end: (C, 2) where it ends (past every sample of the edge).
        needs_exit: (C,) whether ``start`` is still inside the LOR (clearance ascent needed).
        p_dock: (C,) docking probability of the loading move (probsim).
        entropy: (C,) entropy in nats of the predicted stopping feature (IG score).
    """

    edges: np.ndarray
    aim: np.ndarray
    start: np.ndarray
    end: np.ndarray
    needs_exit: np.ndarray
    p_dock: np.ndarray
    entropy: np.ndarray


@dataclass(frozen=True)
class Plan:
    """Planner decision. On ``give_up`` the path is empty and ``target_edge`` is -1."""

    decision: str  # "dock" | "give_up"
    path: np.ndarray  # (L, 2) waypoints; the last segment is the loading move
    p_dock: float
    objective: float
    target_edge: int
    reason: str
    target_point: np.ndarray  # (2,) aimed-at expected edge midpoint (NaN on give-up)
    candidates: Candidates | None = None
    rejected: int = 0  # samples dropped as inconsistent with a recorded slide (``move_ids``)


# m: how far beyond the executor's ``max_slide`` its unrecorded motion after a contact can
# leave the tool from its recorded moves (``retrace``): its retreat and release (0.02 m each)
RETRACE_MARGIN = 0.05


def retrace(
    history: History, start: np.ndarray, space: FreeSpace, step: float, reach: float
) -> np.ndarray | None:
    """Path (L, 2) from ``start`` back along the tool's own free moves to a point outside the
    likely-obstacle region, or None.

    Decision: after a contact the tool rests near its last free segments (the core loop: at
    the end of the last one; the executor: after its retreat, 0.02 m by default, which is not
    recorded), where the posterior's margin often covers it; when ``FreeSpace.ascend`` finds
    no way out (the tool sits on the mean outline), the tool leaves the way it came. It steps
    to the nearest point of the latest free observation within ``reach`` metres, follows
    it back to its start, then earlier ones passing within ``step`` of where the walk stands,
    each back to its start (free observations are recorded in move order, each starting where
    the previous one ended, or, for a plan's first move, where the executor's unrecorded
    retreat along the previous plan's last move left the tool, i.e. on that move, not at its
    end): space the tool has crossed, which no sample consistent with the history intersects.
    Not a hot path: one walk over the history per plan.

    The first step undoes the retreat, or a non-compliant slide the executor ran for evidence
    and reported only as its first contact: a straight, guarded step back, so ``reach`` is
    the executor's ``max_slide`` plus RETRACE_MARGIN (``_lead``). Measured
    2026-11-28 (``bench episode`` on the mock profile, depth prior): with a reach of 0.05 m,
    3 of 4 feasible notch truths gave up "with no way out" after such a slide of 0.1-0.2 m.
    """
    free = np.flatnonzero(np.asarray(history.status) == Status.FREE)
    a, b = history.a[free], history.b[free]
    start = np.asarray(start, float)
    along = b - a
    t = np.sum((start - a) * along, axis=1) / np.maximum(np.sum(along**2, axis=1), 1e-18)
    nearest = a + np.clip(t, 0.0, 1.0)[:, None] * along
    near = np.flatnonzero(np.linalg.norm(nearest - start, axis=1) <= reach)
    if near.size == 0:
        return None
    path = [start] if np.allclose(nearest[near[-1]], start) else [start, nearest[near[-1]]]
    for k in range(near[-1], -1, -1):
        if k < near[-1]:
            u = np.clip((path[-1] - a[k]) @ along[k] / max(along[k] @ along[k], 1e-18), 0, 1)
            on = a[k] + u * along[k]  # the walk's nearest point on move k
            if np.linalg.norm(on - path[-1]) > step:
                continue
            if u < 1 and not np.allclose(on, path[-1]):
                path.append(on)
        path.append(a[k])
        if not space.blocked(a[k])[0]:
            return np.array(path)
    return None


def _lead(
    space: FreeSpace, start: np.ndarray, state: EpisodeState, step: float, max_slide: float
) -> np.ndarray | None:
    """The path's first part: ``start`` alone in free space, else a way out of the
    likely-obstacle region (``FreeSpace.ascend``, then ``retrace``), or None.

    Decision: when the sampler dropped (or deferred) an observation of the latest move, the
    estimate contradicts where the tool just was (notch depth truth 7: it slid down the unseen
    back of a hold, and every contact there was dropped), so the tool first leaves the way it
    came, free or not.
    """
    reach = max_slide + RETRACE_MARGIN
    newest = int(state.move_ids.max(initial=0))  # 0: rows of unknown moves (slides too)
    if newest > 0 and np.isin(np.flatnonzero(state.move_ids == newest), state.ignored).any():
        lead = retrace(state.history, start, space, step, reach)
        if lead is not None:
            return lead
    if not space.blocked(start)[0]:
        return np.array([start])
    lead = space.ascend(start, step)
    return retrace(state.history, start, space, step, reach) if lead is None else lead


def exploration_bonus(aim: np.ndarray, previous: np.ndarray, width: float) -> np.ndarray:
    """B(min_p' d / w) of eq. (24) for aim points (C, 2) against earlier ones (k, 2)."""
    aim = np.asarray(aim, float).reshape(-1, 2)
    previous = np.asarray(previous, float).reshape(-1, 2)
    if len(previous) == 0:
        return np.ones(len(aim))
    if width <= 0:
        return np.ones(len(aim))  # w = 0 is the greedy limit of eq. (24)
    d = np.linalg.norm(aim[:, None, :] - previous[None, :, :], axis=2).min(axis=1)
    return 1.0 - np.exp(-d / width)


def terminal_segments(
    samples: np.ndarray,
    edges: np.ndarray,
    load: np.ndarray,
    space: FreeSpace,
    step: float,
) -> dict[str, np.ndarray]:
    """Optimal terminal segment of every edge facing ``load`` (all edges at once).

    Each aims at the edge's expected midpoint along ``load``. Going backward (along -load) from
    the aim, the start is the first ray point outside the LOR provided the clearance from the
    mean shape increased all the way; otherwise it is the last point where it still increased
    (``needs_exit``: the prefix continues out of the LOR by clearance ascent). The end lies
    ``2 step`` beyond the farthest sample of the edge along ``load``, so the move reaches the
    edge wherever the samples put it. Edges whose ray never gains clearance are dropped.
    """
    mean = samples.mean(axis=0)
    c, d = mean[edges[:, 0]], mean[edges[:, 1]]
    tangent = d - c
    normal = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)  # outward: right of travel
    normal /= np.maximum(np.linalg.norm(normal, axis=1, keepdims=True), 1e-12)
    facing = normal @ load < -_MIN_FACING
    idx = np.flatnonzero(facing)
    aim = 0.5 * (c[idx] + d[idx])
    if len(idx) == 0:
        empty = np.zeros((0, 2))
        return dict(edges=idx, aim=empty, start=empty, end=empty, needs_exit=np.zeros(0, bool))
    x0, y0, x1, y1 = space.free.bounds
    reach = np.hypot(x1 - x0, y1 - y0)
    t = step * np.arange(1, min(_MAX_RAY_STEPS, int(np.ceil(reach / step))) + 1)
    ray = aim[:, None, :] - t[None, :, None] * load  # (C, K, 2)
    blocked = space.blocked(ray.reshape(-1, 2)).reshape(ray.shape[:2])
    # Only the stretch up to the latest first exit matters: trim before measuring clearance.
    last = int(np.where(blocked.all(axis=1), len(t) - 1, np.argmin(blocked, axis=1)).max()) + 1
    t, ray, blocked = t[:last], ray[:, :last], blocked[:, :last]
    clear = space.clearance(ray.reshape(-1, 2)).reshape(ray.shape[:2])
    gaining = np.diff(np.concatenate([np.zeros((len(idx), 1)), clear], axis=1), axis=1) > 0
    k_stall = np.where(gaining.all(axis=1), len(t), np.argmin(gaining, axis=1))
    k_free = np.where((~blocked).any(axis=1), np.argmin(blocked, axis=1), len(t))
    exits = k_free < k_stall
    k_start = np.where(exits, k_free, k_stall - 1)
    ok = k_start >= 0
    rows = np.arange(len(idx))
    start = ray[rows, np.maximum(k_start, 0)]
    ends = samples[:, edges[idx]]  # (N, C, 2, 2): both endpoint samples of each edge
    along = np.einsum("sjkd,d->sjk", ends - aim[None, :, None, :], load)
    reach_past = np.maximum(along.max(axis=(0, 2)), 0.0)
    end = aim + (reach_past + 2 * step)[:, None] * load
    return {
        "edges": idx[ok],
        "aim": aim[ok],
        "start": start[ok],
        "end": end[ok],
        "needs_exit": ~exits[ok],
    }


def holding_frequencies(
    samples: np.ndarray, closed: bool, load, friction: float, closure_edges=()
) -> tuple[np.ndarray, np.ndarray]:
    """Fraction of posterior samples in which each edge (E,) / vertex (2, n) can hold the load.

    An edge holds when it faces the load and slips neither way (eq. 12); a vertex traps a
    slide arriving on one side when the edge on the other side faces the load without carrying
    the slide on (Sec. V-A2): row 0, a left slide along r(v) and l(v) does not slip left; row 1,
    a right slide along l(v) and r(v) does not slip right (the rows of
    ``probsim.DockEstimate.p_stop_vertex_sides``). Polyline ends never trap. These are eq.
    (19)'s sample estimates of the events P(F holds), over samples that satisfy every history
    constraint exactly.

    Decision: ``closure_edges`` (``GaussianShape.closure_edges``: perception's tails past the
    slice ends) and the vertices on them hold nothing. A tail is the ray past what the camera
    saw, not a surface; flatter than the friction angle it looked like a sure hold (P_dock
    0.98-1.0 for 12 cycles on three_ledges truths 9 and 19, with a camera that sees the whole
    wall: no contact ever came, and the rigid tail could not learn).
    """
    edges, left, right = simulate.edge_index_arrays(samples.shape[1], closed)
    flags = simulate.edge_flags(samples, closed, load, friction)  # (N, E, 3)
    slip_left, slip_right, faces = flags[..., 0], flags[..., 1], flags[..., 2]
    holds = faces & ~slip_left & ~slip_right
    pad = np.zeros((len(samples), 1), dtype=bool)  # edge index -1 (missing neighbour)
    sl, sr, fa = (np.hstack([x, pad]) for x in (slip_left, slip_right, faces))
    ends = (left < 0) | (right < 0)
    trap = np.stack(
        [sl[:, right] & fa[:, left] & ~sl[:, left], sr[:, left] & fa[:, right] & ~sr[:, right]],
        axis=1,
    )
    q_edge, q_vertex = holds.mean(axis=0), np.where(ends, 0.0, trap.mean(axis=0))
    closure = np.asarray(closure_edges, dtype=int)
    q_edge[closure] = 0.0
    q_vertex[:, edges[closure].ravel()] = 0.0
    return q_edge, q_vertex


def give_up_draws(threshold: float) -> int:
    """Draws in which no hold bounds P(hold) below ``threshold`` at 95 % (the rule of three):
    ``ceil(3 / threshold)``, at most ``PRIOR_DRAWS_MAX`` (also for a threshold of 0)."""
    if threshold <= 0:
        return PRIOR_DRAWS_MAX
    return min(PRIOR_DRAWS_MAX, int(np.ceil(3 / threshold)))


def edge_holds_anywhere(samples: np.ndarray, shape: GaussianShape, load) -> bool:
    """Whether any of ``samples`` (N, n, 2) lets an edge of ``shape`` hold ``load``
    (``holding_frequencies``). If none does, a non-compliant move docks nowhere: a vertex
    only traps a slide, which only compliant moves make."""
    q_edge, _ = holding_frequencies(
        samples, shape.closed, load, shape.friction, shape.closure_edges
    )
    return bool(q_edge.any())


def first_cycle_draws(
    shape: GaussianShape, state: EpisodeState, n_samples: int, threshold: float
) -> np.ndarray:
    """Prior draws (M, n, 2) that a would-be give-up also counts (module docstring): before any
    observation (empty history: the posterior is ``shape``), ``ceil(3 / threshold)`` (at most
    ``PRIOR_DRAWS_MAX``) minus the ``n_samples`` the planner has; none (M = 0) otherwise."""
    extra = 0 if len(state.history) else max(0, give_up_draws(threshold) - n_samples)
    rng = np.random.default_rng(PRIOR_DRAWS_SEED)
    return shape.vertices(shape.sample_z(rng, extra))


def capped_p_dock(stop_vertex, stop_edge, holding) -> np.ndarray:
    """P_dock (...,) from probsim's stop distributions (``stop_vertex`` (..., 2, n) by arrival,
    ``stop_edge`` (..., E)), each feature's term capped at the sample frequency of that feature
    holding the load (``holding_frequencies``).

    Decision (the paper uses one estimator): P(stop at F) <= P(F holds), and the posterior
    samples satisfy the history constraints exactly while probsim's moment-fit Gaussian does
    not (a slip observation leaves the slipped edge a few per cent of sticking under the fit).
    The cap removes such features; a feature no sample lets hold counts zero (resolution 1/N,
    as in eq. 19). A vertex is two features, one per side a slide arrives from: a slide that
    the samples all carry over a vertex (``slides``: it separated there) must not keep the trap
    that a slide from the other side would meet. Mass removed from a feature is not passed on
    down the slide.
    """
    q_edge, q_vertex = holding
    edges = np.minimum(stop_edge, q_edge).sum(axis=-1)
    return np.clip(edges + np.minimum(stop_vertex, q_vertex).sum(axis=(-2, -1)), 0.0, 1.0)


def whole_path_p_dock(
    posterior: GaussianShape,
    samples: np.ndarray,
    path: np.ndarray,
    load: np.ndarray,
    compliant: bool,
    holding: tuple[np.ndarray, np.ndarray],
    prior_draws: np.ndarray | None = None,
) -> float:
    """P_dock of a whole path (L, 2): probsim's estimate under ``posterior`` (the terminal
    move's P_dock times P(the prefix touches nothing)), capped per feature
    (``capped_p_dock``), and 0 when the path docks on none of the ``samples`` (N, n, 2) nor
    of the first cycle's ``prior_draws`` (``first_cycle_draws``; checked only when no sample
    docks).

    Decision: the per-feature cap cannot see that a feature some samples let hold lies, in
    exactly those samples, where this path does not stop on it. A repeat of a move already
    seen to slip then kept 0.2-1 % (non-compliant sloper, depth prior: the same slip point
    was re-planned 3 times in 12 cycles and the episode never gave up) while eq. (19)'s
    estimator, over samples that satisfy the history, says 0. As for the cap, the
    resolution is 1/N.
    """
    whole = probsim.dock_probability(posterior, path, load, compliant)
    p_dock = float(capped_p_dock(whole.p_stop_vertex_sides, whole.p_stop_edge, holding))
    if p_dock == 0.0:
        return 0.0
    for draws in (samples, prior_draws):
        if draws is not None and len(draws):
            docks = simulate.dock_outcomes(
                draws, posterior.closed, path, posterior.friction, load, compliant
            )
            if docks.any():
                return p_dock
    return 0.0


def evaluate(
    posterior: GaussianShape,
    segments: dict[str, np.ndarray],
    load: np.ndarray,
    compliant: bool,
    holding: tuple[np.ndarray, np.ndarray] | None = None,
) -> Candidates:
    """P_dock and stop-feature entropy of every terminal segment at once (steps 3-4, Sec. V-B).

    ``holding`` (from ``holding_frequencies``) caps probsim's per-feature stop probabilities
    (``capped_p_dock``).
    """
    p_dock, stop_vertex, stop_edge = probsim.dock_probabilities(
        posterior, segments["start"], segments["end"], load, compliant
    )
    if holding is not None:
        p_dock = capped_p_dock(stop_vertex, stop_edge, holding)
    stops = np.hstack([stop_vertex.sum(axis=1), stop_edge])
    outcome = np.clip(np.hstack([stops, 1.0 - stops.sum(axis=1, keepdims=True)]), 0.0, 1.0)
    entropy = -np.sum(outcome * np.log(np.where(outcome > 0, outcome, 1.0)), axis=1)
    return Candidates(**segments, p_dock=p_dock, entropy=entropy)


def score(
    candidates: Candidates,
    objective: str,
    previous_targets: np.ndarray,
    width: float,
    give_up_threshold: float,
) -> np.ndarray:
    """(C,) planning score; candidates scoring 0 are never planned.

    - ``ours``: eq. (24), P_dock * B(min d / w).
    - ``greedy``: P_dock (eq. 24 with w = 0).
    - ``window`` (GW, Sec. VI-A): the first plan takes the best P_dock; later plans take the
      untried site (no earlier aim within w) nearest to that first site among sites with
      P_dock >= the give-up threshold; score 1 / (1 + distance / w).
    - ``info_gain`` (IG probe, Sec. VI-A): the paper does not define the gain; we use the
      entropy (nats) of the predicted outcome, i.e. which feature the move sticks at, or none.
    """
    previous = np.asarray(previous_targets, float).reshape(-1, 2)
    if objective == "ours":
        return candidates.p_dock * exploration_bonus(candidates.aim, previous, width)
    if objective == "greedy" or (objective == "window" and len(previous) == 0):
        return candidates.p_dock
    if objective == "window":
        untried = exploration_bonus(candidates.aim, previous, width) > 1.0 - np.exp(-1.0)
        distance = np.linalg.norm(candidates.aim - previous[0], axis=1)
        eligible = untried & (candidates.p_dock >= give_up_threshold)
        return np.where(eligible, 1.0 / (1.0 + distance / width), 0.0)
    if objective == "info_gain":
        return candidates.entropy
    raise ValueError(f"unknown objective {objective!r}; choose from {OBJECTIVES}")


# give-ups for want of a path, not for want of a hold (``bench episode`` counts them apart)
NO_WAY_OUT = "the tool is inside the likely-obstacle region with no way out"
NO_PREFIX = "no collision-free prefix to any promising docking site"


def _candidates(samples, shape, state, config, posterior, segments):
    """``(candidates, holding, prior draws or None)``: the sites' P_dock capped over the samples;
    a would-be first-cycle give-up recounts the caps with ``first_cycle_draws`` (module
    docstring)."""
    load = np.asarray(config.load)

    def capped(draws):
        holding = holding_frequencies(
            draws, shape.closed, load, shape.friction, shape.closure_edges
        )
        return evaluate(posterior, segments, load, config.compliant, holding), holding

    candidates, holding = capped(samples)
    if candidates.p_dock.max() >= config.give_up_threshold:
        return candidates, holding, None
    extra = first_cycle_draws(shape, state, len(samples), config.give_up_threshold)
    if not len(extra):
        return candidates, holding, None
    return *capped(np.concatenate([samples, extra])), extra


def _give_up(rejected: int, reason: str, candidates: Candidates | None = None) -> Plan:
    return Plan(
        "give_up", np.zeros((0, 2)), 0.0, 0.0, -1, reason, np.full(2, np.nan), candidates, rejected
    )


def _check_inputs(samples: np.ndarray, shape: GaussianShape, state: EpisodeState) -> None:
    if samples.ndim != 3 or samples.shape[1:] != (shape.n_vertices, 2) or len(samples) < 2:
        raise ValueError(
            f"samples must be (N >= 2, {shape.n_vertices}, 2) for this shape, got {samples.shape}"
        )
    if not np.all(np.isfinite(samples)):
        raise ValueError("samples must be finite")
    if state.tool is None:
        raise ValueError("the tool position is unknown (EpisodeState.tool)")


def _why_no_path(objective, order, unreachable, outside: int, threshold: float) -> str:
    """The give-up reason when no candidate site got a plan (``plan``'s path loop)."""
    if not order:
        return f"no candidate site scores above 0 under {objective!r}"
    if unreachable:
        return (
            f"best docking probability of a whole path {max(unreachable):.2e} < threshold "
            f"{threshold:g} ({len(unreachable)} sites' paths)"
        )
    return (
        f"{outside} sites' paths leave the workspace box, no other path" if outside else NO_PREFIX
    )


def plan(
    samples: np.ndarray, shape: GaussianShape, state: EpisodeState, config: PlannerConfig
) -> Plan:
    """Best docking plan for posterior vertex samples (N, n, 2), or a give-up (Sec. V-B).

    Args:
        samples: posterior vertex samples; their moment fit is the Gaussian of the estimate.
        shape: prior (topology: ``closed``, edges; vertex count; ``friction``, the Coulomb
            coefficient).
        state: the episode so far. The samples already satisfy each history row (eq. 13); the
            planner reads the history only for the slides: samples on which a recorded
            compliant slide (``state.move_ids``; rows in ``state.ignored`` take no part) could
            not have happened are dropped first (``slides.consistent_with_slides``;
            ``Plan.rejected`` counts them). Decision: if fewer than two pass (the moment fit
            needs two) all are kept; the count tells. The plan starts at ``state.tool`` and
            eq. (24)'s bonus keeps away from ``state.targets``.
        config: the planner settings (``PlannerConfig``).

    Decision (Sec. III-B gives up when the best P_dock is below the threshold): the threshold
    applies to the whole path's P_dock, which multiplies in the probability that the way there
    touches nothing. A docking site whose path falls below it is passed over, and when every
    site tried is, the planner gives up: on the depth prior an unseen ledge under an overhang
    kept the best loading move's P_dock at 0.01-0.05 while every way to it passed the
    overhang (whole path 1e-4 to 2e-3), and infeasible truths ran to the cycle cap. IG's probes
    (``info_gain``) are not docking attempts and keep their site.

    Raises ValueError on malformed input; an infeasible situation is a give-up with a reason.
    """
    samples = np.asarray(samples, float)
    _check_inputs(samples, shape, state)
    start, load, friction = state.tool, np.asarray(config.load), shape.friction
    objective, compliant = config.objective, config.compliant
    keep = slides.consistent_with_slides(
        samples, shape.closed, state.history, state.move_ids, load, friction, state.ignored
    )
    rejected = int(len(keep) - keep.sum())
    samples = samples[keep] if keep.sum() >= 2 else samples
    step = 0.5 * config.contact_resolution
    lor = likely_obstacle_region(samples, shape.edges, margin=step)
    free = state.history.status == Status.FREE
    visited = np.vstack([start, state.history.a[free], state.history.b[free]])
    space = FreeSpace(lor, samples.mean(axis=0), shape.closed, visited)
    segments = terminal_segments(samples, shape.edges, load, space, step)
    if len(segments["edges"]) == 0:
        return _give_up(rejected, "no edge of the shape faces the load direction")
    posterior = GaussianShape.from_samples(samples, shape.closed, friction)
    candidates, holding, extra = _candidates(samples, shape, state, config, posterior, segments)
    best = float(candidates.p_dock.max())
    if best < config.give_up_threshold:
        return _give_up(
            rejected,
            f"best docking probability {best:.2e} < threshold {config.give_up_threshold:g}",
            candidates,
        )
    lead = _lead(space, start, state, step, config.max_slide)
    if lead is None:
        return _give_up(rejected, NO_WAY_OUT)
    values = score(
        candidates, objective, state.targets, config.contact_resolution, config.give_up_threshold
    )
    order = [j for j in np.argsort(-values, kind="stable") if values[j] > 0]
    unreachable = []  # whole-path P_dock of sites whose way there likely touches something
    outside = 0  # sites whose path leaves the executor's workspace box
    for j in order[: config.max_path_attempts]:
        tail = candidates.start[j : j + 1]
        if candidates.needs_exit[j]:
            exit_path = space.ascend(candidates.start[j], step)
            if exit_path is None:
                continue
            tail = exit_path[::-1]
        middle = space.shortest_path(lead[-1], tail[0])
        if middle is None:
            continue
        path = np.vstack([lead[:-1], middle, tail[1:], candidates.end[j]])
        path = path[np.r_[True, np.any(np.diff(path, axis=0) != 0, axis=1)]]
        if space.touches_outline(path[len(lead) - 1 : -1]):  # the lead is known or made free
            continue
        if not config.inside(path):
            outside += 1
            continue
        p_dock = whole_path_p_dock(posterior, samples, path, load, compliant, holding, extra)
        if objective != "info_gain" and p_dock < config.give_up_threshold:
            unreachable.append(p_dock)
            continue
        value = values[j] * p_dock / max(candidates.p_dock[j], 1e-300)
        return Plan(
            "dock",
            path,
            float(p_dock),
            float(value if objective in ("ours", "greedy") else values[j]),
            int(candidates.edges[j]),
            f"{objective}: edge {candidates.edges[j]} with P_dock {p_dock:.3f}",
            candidates.aim[j],
            candidates,
            rejected,
        )
    why = _why_no_path(objective, order, unreachable, outside, config.give_up_threshold)
    return _give_up(rejected, why, candidates)
