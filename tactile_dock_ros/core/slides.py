"""A compliant slide as one piece of evidence (Sec. V-A2 motion model, Sec. III-B).

A slipping loading contact under compliance slides along the surface, in the slip direction,
until it sticks at a feature or separates. The history records the slide as slip observations
(eq. 13): the first contact, then one every 4 cm of every edge the trace crossed
(``crossed_piece_evidence``, for the simulated robot's ``explore.slide_evidence`` and the
executor's ``execution.guarded``). Each observation constrains
only the edge it lands on, so a posterior sample may put a short edge that holds the load
between two of them (three_ledges: ~1 % of the samples on a ledge the tool had slid down, which
kept infeasible episodes from giving up). The slide says more: the tool passed over every edge
from the first contact's edge to the last observation's edge, so each of them faced the load
and slipped the same way. ``consistent_with_slides`` checks that for every sample; the caller
keeps the consistent samples, i.e. conditions the posterior on the whole slide by rejection.
The ground truth always passes (its slide produced the observations).
"""

from __future__ import annotations

import numpy as np

from . import simulate
from .geometry2d import cross
from .history import History, Status

SLIP = {Status.SLIP_LEFT: -1, Status.SLIP_RIGHT: 1}  # edge-index step of the slide direction
EVIDENCE_SPACING_M = 0.04  # m between a slide's slip observations (crossed_piece_evidence)
MIN_PIECE_SINE = 0.5  # crossed pieces closer than 30 degrees to the load give no observation
# slide rows x samples x edges per crossing test. 2,992 three_ledges samples (a give-up's
# draw-on) against 63 slide rows: peak memory 1415 MiB in one block, 97 MiB in blocks of 2**20;
# time 0.89-0.94x alone on a core, 1.08-1.26x with another process on the other (2026-11-29)
CROSSING_BLOCK = 2**20


def crossed_piece_evidence(
    starts, ends, push, contact_resolution: float, status, spacing_m: float = EVIDENCE_SPACING_M
) -> History:
    """The slip observations of the pieces ``starts`` -> ``ends`` (k, 2) of a slide that the tool
    crossed completely after its first contact: each piece cut into parts at most
    ``spacing_m`` long, one observation per part, the observation the first contact gave, at
    the part's middle: a segment ``contact_resolution`` long along the unit ``push`` (the
    load) with the first contact's slip ``status`` (eq. 13).

    Decision: an observation every ``spacing_m`` (EVIDENCE_SPACING_M = 4 cm, two depth-prior
    vertex spacings). The trace shows the surface wherever the tool slid, and each observation
    constrains only the prior edge it lands on: with one per straight piece a 24 cm slide down
    a smooth slope gave 3 observations over the depth prior's 12 edges there, the other 9 kept
    their prior chance to hold, and ``consistent_with_slides`` rejected 96-100 % of the
    posterior samples every cycle, so the planner ignored the slides (sloper truth 1 of
    ``bench docking``, depth prior, compliant: P_dock 0.7-0.9 for 12 cycles). 2 cm (every
    prior edge) was measured too: it made near-critical slopes thin slabs for HMC (cycles of
    3-5 minutes on three_ledges truth 19, the slowest ours cycle 11 s) for the same give-ups on
    sloper. Two per piece were tried (2026-11-24) on the problem priors, when the seed search
    still stalled on the extra rows (it is bounded since).
    Decision: a piece within 30 degrees of ``push`` (|sin| < MIN_PIECE_SINE; e.g. the vertical
    wall below a ledge lip the tool drops along) gives none. A segment along ``push`` crosses
    such a piece only if the surface passes within contact_resolution * sin / 2 of its middle
    (0.1 mm for a wall 2 degrees off the load): no sample of a 2 cm-edge depth prior fits it,
    the seed search failed, and the sampler dropped it and 3-8 good slip rows with it every
    cycle (three_ledges truth 9, depth prior), so the slides were forgotten.
    The pieces are the ground-truth edges the simulated robot slid over
    (``explore.slide_evidence``), or the straight runs of the executor's trace
    (``execution.guarded.crossed_pieces``).
    """
    if not (np.isfinite(spacing_m) and spacing_m > 0):
        raise ValueError(f"evidence spacing must be finite and > 0, got {spacing_m}")
    starts, ends = _split(np.reshape(starts, (-1, 2)), np.reshape(ends, (-1, 2)), spacing_m)
    push = np.asarray(push, float)
    piece = ends - starts
    length = np.linalg.norm(piece, axis=1)
    sine = np.abs(cross(piece, push)) / np.where(length > 0, length, 1.0)
    keep = sine >= MIN_PIECE_SINE
    middle = 0.5 * (starts[keep] + ends[keep])
    half = 0.5 * contact_resolution * push
    return History(middle - half, middle + half, np.full(len(middle), int(status)))


def _split(starts: np.ndarray, ends: np.ndarray, spacing_m: float):
    """Each piece cut into ceil(length / spacing_m) equal parts: (starts, ends) of the parts."""
    parts = np.maximum(np.ceil(np.linalg.norm(ends - starts, axis=1) / spacing_m), 1).astype(int)
    owner = np.repeat(np.arange(len(starts)), parts)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(parts) - parts, parts)  # part index
    delta = (ends - starts)[owner] / parts[owner, None]
    return starts[owner] + k[:, None] * delta, starts[owner] + (k + 1)[:, None] * delta


def slide_groups(history: History, move_ids, dropped=()) -> list[np.ndarray]:
    """Row indices of each slide: the slip rows of one move (``move_ids`` (k,), e.g. the plan
    id of every row) with one slip status, in history order (first contact first). Left out:
    rows whose move is unknown (id <= 0: plan ids start at 1, a ContactSegment without one
    carries 0), the rows in ``dropped`` (those the sampler ignored as inconsistent), and
    slides left with a single row (they say nothing beyond eq. 13)."""
    move_ids = np.asarray(move_ids).reshape(-1)
    if len(move_ids) != len(history):
        raise ValueError(f"move_ids has {len(move_ids)} entries for {len(history)} history rows")
    dropped = np.asarray(dropped, dtype=int).reshape(-1)
    if np.any((dropped < 0) | (dropped >= len(history))):
        raise ValueError(f"dropped rows {dropped.tolist()} outside the {len(history)}-row history")
    slip = np.isin(history.status, list(SLIP)) & (move_ids > 0)
    slip[dropped] = False
    keys = np.unique(np.stack([move_ids[slip], history.status[slip]], axis=1), axis=0)
    groups = [
        np.flatnonzero(slip & (move_ids == move) & (history.status == status))
        for move, status in keys
    ]
    return [g for g in groups if len(g) >= 2]


def consistent_with_slides(
    vertices: np.ndarray,
    closed: bool,
    history: History,
    move_ids,
    load,
    friction: float,
    dropped=(),
) -> np.ndarray:
    """(N,) whether each sample (N, n, 2) lets every recorded slide happen.

    For a slide with rows r_0 (first contact) .. r_k: the edge each row's segment lands on
    (first crossing, eqs. 4-10) must lie at or beyond r_0's edge in the slide direction, and
    every edge from r_0's edge to the farthest of them must face the load and slip that way
    (eq. 12's cones), so no edge sticks and no vertex traps on the way. Decision: a row that
    lands on no edge of a sample is left out for that sample, and a slide whose first contact
    lands nowhere constrains it not at all: the sampler already checked each row (eq. 13), so
    such a row is one the sampler's model and the exact crossing test disagree on, not
    evidence against the sample. The truth passes for loading moves along the load (the
    planner's terminal segments): ``crossed_piece_evidence`` reports only edges the slide
    crossed on the way down.
    """
    vertices = np.asarray(vertices, float)
    groups = slide_groups(history, move_ids, dropped)
    if not groups or not len(vertices):
        return np.ones(len(vertices), dtype=bool)
    edges, _, _ = simulate.edge_index_arrays(vertices.shape[1], closed)
    rows = sum(len(g) for g in groups)
    block = max(1, CROSSING_BLOCK // (rows * len(edges)))  # samples per crossing test
    return np.concatenate(
        [
            _consistent_block(
                vertices[i : i + block], closed, history, groups, edges, load, friction
            )
            for i in range(0, len(vertices), block)
        ]
    )


def _consistent_block(vertices, closed, history, groups, edges, load, friction) -> np.ndarray:
    """``consistent_with_slides`` for samples (N, n, 2) whose crossing test fits one block."""
    ok = np.ones(len(vertices), dtype=bool)
    count = len(edges)
    c, d = vertices[:, edges[:, 0]], vertices[:, edges[:, 1]]
    flags = simulate.friction_functionals(load, friction) @ np.moveaxis(d - c, -1, -2) > 0.0
    slip_left, slip_right, faces = flags[:, 0], flags[:, 1], flags[:, 2]  # (N, E) each
    rows = np.concatenate(groups)
    shape = (len(rows), *c.shape)  # every slide row against every sample in one crossing test
    hit, host, _, _ = simulate.first_hits(
        np.broadcast_to(c, shape).reshape(-1, *c.shape[1:]),
        np.broadcast_to(d, shape).reshape(-1, *d.shape[1:]),
        np.repeat(history.a[rows], len(vertices), axis=0),
        np.repeat(history.b[rows], len(vertices), axis=0),
    )
    landed, hosts = hit.reshape(len(rows), -1).T, host.reshape(len(rows), -1).T
    start = 0
    for group in groups:
        h, hit = hosts[:, start : start + len(group)], landed[:, start : start + len(group)]
        start += len(group)
        step = SLIP[Status(int(history.status[group[0]]))]
        offset = step * (h - h[:, :1])
        if closed:
            offset %= count
        offset = np.where(hit, offset, 0)
        along = step * (np.arange(count)[None, :] - h[:, :1])
        if closed:
            along %= count
        reach = offset.max(axis=1, keepdims=True)
        span = (along >= 0) & (along <= reach)
        carries = faces & (slip_right if step > 0 else slip_left)
        fails = np.any(offset < 0, axis=1) | np.any(span & ~carries, axis=1)
        ok &= ~(hit[:, 0] & (fails | _traps_after(along, reach, carries, faces)))
    return ok


def _traps_after(along, reach, carries, faces) -> np.ndarray:
    """(N,) whether the slide, carried on past its farthest row, would have stuck at a vertex.

    A slide is recorded as a group only when it ended by separating (``explore.slide_evidence``
    and ``execution.guarded`` give the crossed pieces only then; the move did not dock). Past
    the farthest row's edge the tool goes on over the edges that carry it, up to the first
    edge that does not: if that edge faces the load the tool would have been trapped at the
    vertex before it (docked, Sec. V-A2), which did not happen; a sample that says so fails.
    A walk off an open polyline's end is a separation. ``along`` (N, E) counts edges from the
    first contact's edge in the slide direction (modulo E when closed; behind it negative),
    ``reach`` (N, 1) >= 0 the farthest row's count.
    """
    count = along.shape[1]
    beyond = np.where((along > reach) & ~carries, along - reach, count + 1)
    first = beyond.argmin(axis=1)
    rows = np.arange(len(first))
    return (beyond[rows, first] <= count) & faces[rows, first]
