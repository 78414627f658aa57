"""History-consistency constraints g1..g6 and f_free, f_coll, f_H (paper Sec. IV-A..C, eqs. 1-13).

For an observation segment ab and a shape edge cd, write y = (c_x, c_y, d_x, d_y), r = b - a,
e = d - c and cross(u, v) = u_x v_y - u_y v. Every primitive is a quadratic in y,
``g(y) = s * quad(y) + l . y + k`` with ``quad(y) = c_y d_x - c_x d_y`` (the y^T Q y of eq. 11):

- g1 = cross(e, a - c)   (eq. 7: a is right of cd, outside the solid)
- g2 = -cross(e, b - c)  (eq. 8: b is left of cd, inside)
- g3 = -cross(r, c - a)  (eq. 9: c is left of ab)
- g4 = cross(r, d - a)   (eq. 10: d is right of ab)
- g5, g6 (eq. 13): the reversed motion b - a lies in the friction cone Cone(lo, hi) of the
  status (stick, slip left or slip right; the cone edges are linear in e), as
  g5 = cross(lo, r) <= 0 and g6 = cross(r, hi) <= 0. Units: square metres.

All of g1..g4 <= 0 means ab enters the solid across cd (alpha > 0 in eq. 6); all >= 0 means
it leaves across cd. Decisions where the paper is loose:

- A *contact* observation requires some edge with g1..g4 (and g5, g6 for stick/slip) <= 0, i.e.
  the tool entered the solid across that edge (eq. 2 with the 6-constraint pair of Sec. IV-C).
- A *free* observation forbids crossings in either direction (eq. 1 only forbids entering; a
  free segment starting inside a sampled solid would otherwise go unnoticed). Per pair
  ``f = max(-max_k g_k, min_k g_k)``: positive iff the four g share a sign. The reversed
  crossing has the same roots, so this costs nothing in range determination.
- Boundary cases (some g exactly 0, measure zero under the prior) count as touching.

``f_H`` (eq. 3) is the max over observations of these values; a state is consistent iff every
observation's value is <= 0.
"""

from __future__ import annotations

import numpy as np
from scipy.special import ndtr

from .geometry2d import cross
from .history import History, Status
from .shape import GaussianShape

N_SLOTS = 6  # primitives per (observation, edge) pair: g1..g6

_ROT_CW = np.array([[0.0, 1.0], [-1.0, 0.0]])  # e -> outward normal n = (e_y, -e_x)
_J = np.array([[0.0, 1.0], [-1.0, 0.0]])  # cross(u, v) = u^T J v


def _cone_matrices(status: int, mu: float) -> tuple[np.ndarray, np.ndarray] | None:
    """(L, H) with cone edges lo = L e, hi = H e (hi CCW of lo) for a contact status (Sec. IV-C)."""
    eye = np.eye(2)
    if status == Status.STICK:
        return _ROT_CW - mu * eye, _ROT_CW + mu * eye
    if status == Status.SLIP_LEFT:
        return _ROT_CW + mu * eye, eye
    if status == Status.SLIP_RIGHT:
        return -eye, _ROT_CW - mu * eye
    return None


def observation_primitives(history: History, friction: float) -> tuple[np.ndarray, ...]:
    """Coefficients of g1..g6 for each observation: sign (k, 6), lin (k, 6, 4), const (k, 6),
    active (k, 6) bool (g5, g6 exist only for stick/slip)."""
    if not np.isfinite(friction) or friction < 0:
        raise ValueError(f"friction must be finite and >= 0, got {friction}")
    k = len(history)
    a, b = history.a, history.b
    r = b - a
    cab = cross(a, b)
    sign = np.zeros((k, N_SLOTS))
    lin = np.zeros((k, N_SLOTS, 4))
    const = np.zeros((k, N_SLOTS))
    active = np.zeros((k, N_SLOTS), dtype=bool)
    active[:, :4] = True
    sign[:, 0], sign[:, 1] = -1.0, 1.0
    lin[:, 0] = np.stack([-a[:, 1], a[:, 0], a[:, 1], -a[:, 0]], axis=1)
    lin[:, 1] = np.stack([b[:, 1], -b[:, 0], -b[:, 1], b[:, 0]], axis=1)
    lin[:, 2, :2] = np.stack([r[:, 1], -r[:, 0]], axis=1)
    const[:, 2] = -cab
    lin[:, 3, 2:] = np.stack([-r[:, 1], r[:, 0]], axis=1)
    const[:, 3] = cab
    for i, status in enumerate(history.status):
        cone = _cone_matrices(int(status), friction)
        if cone is None:
            continue
        low, high = cone
        w5 = low.T @ _J @ r[i]  # cross(L e, r) = (L^T J r) . e
        w6 = high.T @ _J.T @ r[i]  # cross(r, H e) = (H^T J^T r) . e
        lin[i, 4] = np.concatenate([-w5, w5])
        lin[i, 5] = np.concatenate([-w6, w6])
        active[i, 4:] = True
    return sign, lin, const, active


def quad(y: np.ndarray) -> np.ndarray:
    """y^T Q y = c_y d_x - c_x d_y for y (..., 4)."""
    return y[..., 1] * y[..., 2] - y[..., 0] * y[..., 3]


def bilinear(y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Symmetric bilinear form y^T Q w of ``quad``."""
    return 0.5 * (y[..., 1] * w[..., 2] + w[..., 1] * y[..., 2]) - 0.5 * (
        y[..., 0] * w[..., 3] + w[..., 0] * y[..., 3]
    )


class PairStructure:
    """The max/min structure of f_H over a list of (observation, edge) pairs (eqs. 1-3, 16-17).

    ``pairs`` (P, 2) holds (observation index, edge index), any order; observations of a free
    status without pairs are satisfied, contact observations without pairs are violated.
    """

    def __init__(self, status: np.ndarray, pairs: np.ndarray):
        self.status = np.asarray(status, dtype=int)
        pairs = np.asarray(pairs, dtype=int).reshape(-1, 2)
        order = np.argsort(pairs[:, 0], kind="stable")
        self.pairs = pairs[order]
        self.n_obs = len(self.status)
        obs = self.pairs[:, 0]
        self.free_pair = self.status[obs] == Status.FREE
        counts = np.bincount(obs, minlength=self.n_obs)
        self.nonempty = np.flatnonzero(counts)
        self.starts = (np.cumsum(counts) - counts)[self.nonempty]
        self.free_obs = self.status == Status.FREE

    def pair_values(self, g: np.ndarray) -> np.ndarray:
        """Per-pair values (..., P): free ``max(-max_k g, min_k g)`` (> 0 iff the segment
        crosses the edge), contact ``max_k g`` (<= 0 iff it enters across the edge)."""
        g4 = g[..., :4]
        free_val = np.maximum(-g4.max(axis=-1), g4.min(axis=-1))
        return np.where(self.free_pair, free_val, g.max(axis=-1))

    def reduce(self, g: np.ndarray) -> np.ndarray:
        """Per-observation values f_{s,a,b} (..., k) from pair primitive values g (..., P, 6).

        Inactive slots must hold -inf. Consistent iff all values are <= 0.
        """
        return self.reduce_pairs(self.pair_values(g))

    def reduce_pairs(self, pair: np.ndarray) -> np.ndarray:
        """Per-observation values (..., k) from per-pair values (..., P)."""
        out = np.where(self.free_obs, -np.inf, np.inf) * np.ones((*pair.shape[:-1], self.n_obs))
        if len(self.pairs) == 0:
            return out
        # free observations take the max over pairs, contact ones the min: negate to share min
        q = np.where(self.free_pair, -pair, pair)
        m = np.minimum.reduceat(q, self.starts, axis=-1)
        out[..., self.nonempty] = np.where(self.free_obs[self.nonempty], -m, m)
        return out


def pair_values(
    y: np.ndarray, sign: np.ndarray, lin: np.ndarray, const: np.ndarray, active: np.ndarray
) -> np.ndarray:
    """Primitive values g (..., P, 6) for edge coordinates y (..., P, 4) and per-pair
    coefficients (P, 6[, 4]); inactive slots are -inf."""
    g = sign * quad(y)[..., None] + np.einsum("...pj,pkj->...pk", y, lin) + const
    return np.where(active, g, -np.inf)


def _check_vertices(vertices: np.ndarray) -> np.ndarray:
    v = np.asarray(vertices, dtype=float)
    if v.ndim == 2:
        v = v[None]
    if v.ndim != 3 or v.shape[-1] != 2 or v.shape[1] < 2:
        raise ValueError(f"vertices must have shape (N, n >= 2, 2), got {np.shape(vertices)}")
    if not np.all(np.isfinite(v)):
        raise ValueError("vertices must be finite")
    return v


def _edges(n: int, closed: bool) -> np.ndarray:
    first = np.arange(n if closed else n - 1)
    return np.stack([first, (first + 1) % n], axis=1)


def observation_violations(
    shape_closed: bool,
    vertices: np.ndarray,
    history: History,
    friction: float,
    primitives: tuple[np.ndarray, ...] | None = None,
) -> np.ndarray:
    """Exact per-observation values f_{s,a,b} (N, k) for vertex sets (N, n, 2); <= 0 = satisfied.

    Batch bounding-volume check (Sec. IV-F): a pair whose segment box misses the box of the edge
    over the whole batch is never evaluated (it cannot touch, so its free value is -inf and it
    cannot serve a contact). ``primitives``: ``observation_primitives(history, friction)``,
    for callers that evaluate one history many times (computed here when None).
    """
    v = _check_vertices(vertices)
    k = len(history)
    if k == 0 or len(v) == 0:
        return np.zeros((len(v), k))
    ends = v[:, _edges(v.shape[1], shape_closed)]  # (N, E, 2, 2)
    pairs = _box_pairs(history, np.arange(k), ends)
    if primitives is None:
        primitives = observation_primitives(history, friction)
    sign, lin, const, active = primitives
    structure = PairStructure(history.status, pairs)
    obs = structure.pairs[:, 0]
    y = ends[:, structure.pairs[:, 1]].reshape(len(v), len(obs), 4)
    g = pair_values(y, sign[obs], lin[obs], const[obs], active[obs])
    return structure.reduce(g)


def _box_pairs(history: History, rows: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """(P, 2) (observation, edge) pairs, in row order, of the observations ``rows`` whose
    segment's bounding box meets the box of the edge over the batch ``ends`` (N, E, 2, 2): the
    bounding-volume check of Sec. IV-F (no other pair can touch)."""
    a, b = history.a[rows], history.b[rows]
    seg_lo, seg_hi = np.minimum(a, b), np.maximum(a, b)
    edge_lo, edge_hi = ends.min(axis=(0, 2)), ends.max(axis=(0, 2))
    overlap = np.all(
        (seg_lo[:, None] <= edge_hi[None]) & (edge_lo[None] <= seg_hi[:, None]), axis=-1
    )
    pairs = np.argwhere(overlap)
    pairs[:, 0] = rows[pairs[:, 0]]
    return pairs


def crossed_free_pairs(shape_closed: bool, vertices: np.ndarray, history: History) -> np.ndarray:
    """(Q, 2) (observation, edge) pairs, in row order, of the free observations that some vertex
    set (N, n, 2) crosses (free pair value > 0, ``PairStructure.pair_values``): over every
    edge, not a pruned list (the pairs a pruned constraint system missed)."""
    v = _check_vertices(vertices)
    free = np.flatnonzero(history.status == Status.FREE)
    if free.size == 0 or len(v) == 0:
        return np.zeros((0, 2), dtype=int)
    ends = v[:, _edges(v.shape[1], shape_closed)]
    pairs = _box_pairs(history, free, ends)
    sign, lin, const, active = observation_primitives(history, 0.0)  # free rows: no cone
    obs = pairs[:, 0]
    y = ends[:, pairs[:, 1]].reshape(len(v), len(pairs), 4)
    g = pair_values(y, sign[obs], lin[obs], const[obs], active[obs])
    crossed = PairStructure(history.status, pairs).pair_values(g) > 0  # pairs in row order
    return pairs[np.any(crossed, axis=0)]


def history_consistent(
    shape_closed: bool, vertices: np.ndarray, history: History, friction: float
) -> np.ndarray:
    """(N,) bool: whether each vertex set (N, n, 2) satisfies every observation (f_H <= 0)."""
    return np.all(observation_violations(shape_closed, vertices, history, friction) <= 0, axis=1)


def collision_bounds(shape: GaussianShape, history: History) -> np.ndarray:
    """(k, E) upper bounds on the prior probability that observation segment i touches edge e.

    Decision (Sec. IV-F asks for the prior collision probability): a separating-axis union
    bound, cheap and conservative. For a unit axis u, if both endpoints of the edge project
    below min(u.a, u.b) the segments cannot meet, so P <= P(u.c >= h) + P(u.d >= h), exact 1-D
    Gaussian tails. Axes tried: both normals and both directions of the segment and the mean
    edge, both signs; the smallest bound is kept.
    """
    a, b = history.a, history.b
    means, covs = shape.edge_gaussians()
    c_mean, d_mean = means[:, :2], means[:, 2:]
    c_cov, d_cov = covs[:, :2, :2], covs[:, 2:, 2:]

    def unit(v):
        norm = np.linalg.norm(v, axis=-1, keepdims=True)
        return np.where(norm > 0, v / np.where(norm > 0, norm, 1.0), 0.0)

    r = unit(b - a)  # (k, 2)
    e = unit(d_mean - c_mean)  # (E, 2)
    k, n_edges = len(a), len(c_mean)
    axes = [np.broadcast_to(v[:, None], (k, n_edges, 2)) for v in (r, r @ _ROT_CW.T)]
    axes += [np.broadcast_to(v[None], (k, n_edges, 2)) for v in (e, e @ _ROT_CW.T)]
    best = np.ones((k, n_edges))
    for axis in axes:
        for u in (axis, -axis):
            h = np.minimum(np.einsum("ked,kd->ke", u, a), np.einsum("ked,kd->ke", u, b))
            bound = np.zeros((k, n_edges))
            for mean, cov in ((c_mean, c_cov), (d_mean, d_cov)):
                mu = np.einsum("ked,ed->ke", u, mean)
                sd = np.sqrt(np.einsum("ked,edf,kef->ke", u, cov, u))
                gap = h - mu
                with np.errstate(divide="ignore", invalid="ignore"):
                    tail = np.where(sd > 0, ndtr(-gap / np.where(sd > 0, sd, 1.0)), gap <= 0)
                bound += tail
            valid = np.linalg.norm(u, axis=-1) > 0
            best = np.where(valid, np.minimum(best, bound), best)
    return np.minimum(best, 1.0)


def prune_pairs(
    shape: GaussianShape, history: History, threshold: float = 1e-4, min_contact_edges: int = 3
) -> np.ndarray:
    """(P, 2) (observation, edge) pairs with prior collision bound >= ``threshold`` (eqs. 16-17).

    A contact observation keeps at least its ``min_contact_edges`` most likely edges, so a
    measurement the prior finds very unlikely still constrains the sampler.
    """
    if len(history) == 0:
        return np.zeros((0, 2), dtype=int)
    bounds = collision_bounds(shape, history)
    keep = bounds >= threshold
    contact = np.flatnonzero(history.is_contact)
    top = np.argsort(-bounds[contact], axis=1)[:, :min_contact_edges]
    keep[contact[:, None], top] = True
    return np.argwhere(keep)
