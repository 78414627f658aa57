"""Closed-form probabilistic simulation of a guarded compliant move (paper Sec. V-A, App. B).

For a Gaussian shape ``x = A z + mu`` this estimates, in O(n) per move, the probability that
executing a path's loading move stops and sticks at each vertex and edge (eqs. 20-22), the same
event the deterministic simulator ``core.simulate`` samples for eq. (19). The motion model and its
edge functionals are those of ``core.simulate``.

Decisions where the paper is vague:

* P(C_e) (App. B): the four exact segment-segment conditions (7-10), written as s >= 0, s <= 1
  (quadratic in the edge, linearized about its mean) and t >= 0, t <= 1 (linear), are evaluated on
  the edge's 4-D Gaussian, either as a product of four univariate probabilities (26) or as the
  product of two bivariate quadrants, pairs (I, III) = (s >= 0, t >= 0) and (II, IV) =
  (s <= 1, t <= 1) (30), or ("sequential", the default of ``dock_probability``) by Mendell-Elston
  conditioning on all of them, with the stick / slide conditions of the loading move in the same
  orthant (P(C_e, K_e) etc.; the pair products assume independence that fails badly when one
  rotation drives both where an edge lies and how it is tilted: benchmark in docs/probsim.md).
  With "univariate" / "bivariate", P(C_e, K_e) = P(C_e) P(K_e | C_e) as in the paper.
* Stick / slide events only involve an edge's direction t = d - c: slide left iff wL.t > 0, slide
  right iff wR.t > 0, faces the load iff wN.t > 0 (``simulate.friction_functionals``). After a
  contact, P(K_e | C_e) = P(K_e) / P(wN.t > 0), since a contact implies the edge faces the move.
* At a vertex v reached by a left slide along r(v) (the paper's P(. | L_r(v)) ~ P(. | SL_r(v))):
  continue iff SL on l(v) and l(v) faces the load; stick iff l(v) faces the load and does not
  slide; separate (undocked) otherwise. The three-event probability is chained through SL_l(v):
  P(SL_l, N_l | SL_r) ~ P(SL_l, SL_r) / P(SL_r) * P(SL_l, N_l) / P(SL_l). Mirror image on the right.
* Contacts of one move are treated as mutually exclusive first contacts; if the P(C_e) of the
  loading move sum to more than 1 they are scaled to sum to 1. Moves before the loading move
  must not touch: p_dock is multiplied by the prefix's no-contact probability, the product over
  its moves of 1 - sum_e P(C_e).
* Degenerate covariances (zero or rank-deficient) give the limit values: a constraint with zero
  variance holds with probability 1 or 0. A zero-length move touches nothing (P(C_e) = 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr, ndtri

from . import bvn, geometry2d
from .geometry2d import unit
from .shape import GaussianShape
from .simulate import edge_index_arrays, friction_functionals

METHODS = ("bivariate", "univariate", "sequential")
L_, R_, N_ = 0, 1, 2  # rows of simulate.friction_functionals: slide left, slide right, facing
_HALF_LOG_2PI = 0.5 * np.log(2.0 * np.pi)


@dataclass(frozen=True)
class DockEstimate:
    """Eqs. (20-22) solved for one path: p_dock = p_prefix_clear * (sum of the stop terms)."""

    p_dock: float
    # (2, n) stop-and-stick probability per vertex, by how the tool arrived: row 0 by a left
    # slide (along r(v)), row 1 by a right slide (along l(v))
    p_stop_vertex_sides: np.ndarray
    p_stop_edge: np.ndarray  # (E,) stop-and-stick probability per edge
    p_prefix_clear: float = 1.0  # probability that the moves before the loading move touch nothing

    @property
    def p_stop_vertex(self) -> np.ndarray:
        """(n,) stop-and-stick probability per vertex, both arrivals."""
        return self.p_stop_vertex_sides.sum(axis=0)


def _standardize(mean: np.ndarray, var: np.ndarray) -> np.ndarray:
    """h = mean / sd with the zero-variance limits: +inf where mean >= 0, -inf where mean < 0."""
    sd = np.sqrt(np.maximum(var, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        h = mean / sd
    return np.where(sd > 0, h, np.where(mean >= 0, np.inf, -np.inf))


def _correlation(cov: np.ndarray, var_a: np.ndarray, var_b: np.ndarray) -> np.ndarray:
    denom = np.sqrt(np.maximum(var_a, 0.0) * np.maximum(var_b, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        rho = cov / denom
    return np.clip(np.where(denom > 0, rho, 0.0), -1.0, 1.0)


def _both_positive(mean_a, var_a, mean_b, var_b, cov_ab) -> np.ndarray:
    """P(X > 0, Y > 0) for jointly Gaussian X, Y: a standard quadrant (eq. 29)."""
    return bvn.quadrant(
        _standardize(mean_a, var_a), _standardize(mean_b, var_b), _correlation(cov_ab, var_a, var_b)
    )


def positive_orthant_sequential(mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """P(all X_i >= 0) for Gaussians mean (k, ...), cov (k, k, ...): Mendell-Elston conditioning.

    Repeatedly takes the least likely remaining condition, multiplies its probability in, and
    replaces the Gaussian by its moment-matched truncation (Gaussian regression of the others).
    Unlike the pair products (26, 30) this stays accurate when the conditions are almost
    deterministically related, e.g. when a single rotation drives all four conditions of (7-10).
    Zero-variance conditions count as certain (mean >= 0) or impossible; k steps, k = 4 here.
    """
    mean = np.asarray(mean, dtype=float)
    k, batch = len(mean), mean.shape[1:]
    flat_mean = mean.reshape(k, -1)  # (k, M)
    flat_cov = np.moveaxis(np.asarray(cov, dtype=float).reshape(k, k, -1), -1, 0)  # (M, k, k)
    count = flat_mean.shape[1]
    col_at = np.arange(count) * (k * k) + np.arange(k)[:, None] * k  # entry (i, 0) of each block

    def column_at(at, out):  # entry (i, j) of each block
        np.add(col_at, at // count, out=out)

    pool = flat_cov.reshape(-1)
    var = np.take(pool, col_at + np.arange(k)[:, None])
    return _orthant_rows(flat_mean.copy(), var, pool, column_at).reshape(batch)


def _orthant_rows(mu: np.ndarray, var: np.ndarray, pool: np.ndarray, column_at) -> np.ndarray:
    """``positive_orthant_sequential`` for S orthants whose covariance entries live in a pool.

    ``mu``, ``var`` (k, S): means and variances, used as work arrays (overwritten). ``pool`` is a
    flat array holding the entries of every covariance, and ``column_at(at, out)`` writes into
    ``out`` (k, S) the pool indices of the column of condition j, where ``at`` (S,) is the flat
    index j * S + r of the chosen condition of orthant r. Orthants sharing entries (events of
    one move and edge) thus need no copies of their blocks. Returns (S,).

    The least likely condition is the one with the smallest standardized mean h, so only its
    probability is evaluated per step. Each truncation is a rank-one downdate of the covariance,
    kept as (gain, shrink) pairs: a step reads only the diagonal and the chosen column of the
    pool, never an updated matrix. Arrays are (k, S) so every step works on contiguous rows.
    h is clipped to [-1e3, 1e3] for the step's factor and truncation: Phi is exactly 0 / 1 there
    in double precision, and a certain or done condition (h = +inf) then shifts nothing.
    """
    k, count = mu.shape
    if not 0 < k <= 16:
        raise ValueError(f"the orthant takes 1 to 16 conditions, got {k}")
    cols = np.arange(count)
    # First least likely condition from the row mask of minima: bit k-1-i flags condition i,
    # so the highest set bit (a table lookup) is the first minimum, as argmin would pick.
    bits = (1 << np.arange(k - 1, -1, -1))[:, None].astype(np.uint16)
    first_set = (k - 1 - np.floor(np.log2(np.maximum(np.arange(1 << k), 1)))).astype(np.intp)
    # Work buffers reused by every step: fewer fresh temporaries, fewer page faults.
    sd, h, tmp = np.empty_like(mu), np.empty_like(mu), np.empty_like(mu)
    index, minimal = np.empty((k, count), dtype=np.intp), np.empty((k, count), dtype=bool)
    downdates = []  # (gain (k, S), shrink (S,)) per step: S -= shrink * gain gain^T
    total = np.ones(count)
    with np.errstate(divide="ignore", invalid="ignore"):  # h of zero-variance conditions
        for step in range(k):
            np.sqrt(np.maximum(var, 0.0, out=sd), out=sd)
            np.divide(mu, sd, out=h)
            np.fmin(h, np.inf, out=h)  # zero variance: +-inf by the sign of mu; 0 / 0 -> +inf
            # Done conditions have mean +inf; when only they and certain (h = +inf) ones are left,
            # whichever is picked changes nothing (factor 1, zero shift and shrink).
            hj = h.min(axis=0)
            if step == k - 1:  # nothing left to condition
                total *= ndtr(np.clip(hj, -1e3, 1e3))
                break
            j = first_set[np.sum(np.equal(h, hj, out=minimal) * bits, axis=0)]
            hj = np.clip(hj, -1e3, 1e3)
            p_j = ndtr(hj)
            total *= p_j
            # Inverse Mills ratio phi / Phi; Phi underflows only where total is already < 1e-300.
            mills = np.exp(-0.5 * hj * hj - _HALF_LOG_2PI) / np.maximum(p_j, 1e-300)
            at = j * count + cols  # flat index of the chosen condition in (k, S)
            var_j = np.take(var, at)
            shift = np.take(sd, at) * mills  # truncated mean minus mean
            shrink = var_j * mills * (hj + mills)  # variance removed by the truncation
            column_at(at, index)
            gain = np.take(pool, index)  # (k, S): column j of each covariance
            for gain_t, shrink_t in downdates:
                gain -= np.multiply(gain_t, np.take(gain_t, at) * shrink_t, out=tmp)
            gain /= np.where(var_j > 0, var_j, np.inf)  # no regression on a constant
            mu += np.multiply(gain, shift, out=tmp)
            np.multiply(gain, shrink, out=tmp)
            var -= np.multiply(gain, tmp, out=tmp)
            downdates.append((gain, shrink))
            np.put(mu, at, np.inf)  # conditioned on: never the least likely again
    return np.clip(total, 0.0, 1.0)


def _check_shape(shape: GaussianShape) -> None:
    if not isinstance(shape, GaussianShape):
        raise TypeError(f"shape must be a GaussianShape, got {type(shape).__name__}")


def _move_endpoints(a, b) -> tuple[np.ndarray, np.ndarray]:
    """Moves as finite (K, 2) arrays; ValueError otherwise."""
    a = np.asarray(a, dtype=float).reshape(-1, 2)
    b = np.asarray(b, dtype=float).reshape(-1, 2)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        raise ValueError("move endpoints must be finite")
    return a, b


def _conditions(a, b, c, d):
    """Conditions (7-10) for move a -> b and edge y = (c, d), all broadcastable (..., 2), as
    functions of y that must be >= 0: values at the mean (4, ...) and gradients (..., 4, 4)
    (condition, then y = (c_x, c_y, d_x, d_y)).

    (I) s >= 0: cross(d - c, c - a), (II) s <= 1: cross(d - c, b - c) (bilinear in y, linearized
    about its mean), (III) t >= 0: cross(b - a, c - a), (IV) t <= 1: cross(b - a, a - d).
    """
    batch = np.broadcast_shapes(a.shape, b.shape, c.shape, d.shape)[:-1]
    mx, my = b[..., 0] - a[..., 0], b[..., 1] - a[..., 1]  # move = b - a
    tx, ty = d[..., 0] - c[..., 0], d[..., 1] - c[..., 1]  # edge direction d - c
    cax, cay = c[..., 0] - a[..., 0], c[..., 1] - a[..., 1]  # c - a
    bcx, bcy = b[..., 0] - c[..., 0], b[..., 1] - c[..., 1]  # b - c
    adx, ady = a[..., 0] - d[..., 0], a[..., 1] - d[..., 1]  # a - d
    bdx, bdy = b[..., 0] - d[..., 0], b[..., 1] - d[..., 1]  # b - d
    values = np.empty((4, *batch))
    values[0] = tx * cay - ty * cax  # (I) cross(d - c, c - a): a on the outer side of cd
    values[1] = tx * bcy - ty * bcx  # (II) cross(d - c, b - c): b on the inner side
    values[2] = mx * cay - my * cax  # (III) cross(b - a, c - a): c left of ab
    values[3] = mx * ady - my * adx  # (IV) cross(b - a, a - d): d right of ab
    grads = np.zeros((*batch, 4, 4))  # rows: rot(d - a), rot(a - c); rot(b - d), rot(c - b); ...
    grads[..., 0, 0], grads[..., 0, 1], grads[..., 0, 2], grads[..., 0, 3] = ady, -adx, cay, -cax
    grads[..., 1, 0], grads[..., 1, 1], grads[..., 1, 2], grads[..., 1, 3] = -bdy, bdx, bcy, -bcx
    grads[..., 2, 0], grads[..., 2, 1] = -my, mx  # rot(b - a), 0
    grads[..., 3, 2], grads[..., 3, 3] = my, -mx  # 0, -rot(b - a)
    return values, grads


def _collision_conditions(a, b, means):
    """``_conditions`` for every pair of moves a, b (K, 2) and edge means (E, 4): values
    (4, K, E), gradients (K, E, 4, 4) and the zero-length moves (K, 1)."""
    a, b = _move_endpoints(a, b)
    values, grads = _conditions(a[:, None], b[:, None], means[None, :, :2], means[None, :, 2:])
    still = np.linalg.norm(b - a, axis=-1)[:, None] == 0.0
    return values, grads, still


def segment_collision_probabilities(a, b, means, covs, method: str = "bivariate") -> np.ndarray:
    """P(ab hits cd) for moves a, b (K, 2) and edges y = (c, d) ~ N(means (E, 4), covs (E, 4, 4)).

    ``method``: "univariate" (26), "bivariate" (30, pairs (I, III) and (II, IV)) or "sequential"
    (``positive_orthant_sequential`` on all four). Returns (K, E).
    """
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    values, grads, still = _collision_conditions(a, b, means)
    cov_g = np.moveaxis(grads @ covs @ np.swapaxes(grads, 2, 3), (2, 3), (0, 1))  # (4, 4, K, E)
    var = np.stack([cov_g[i, i] for i in range(4)])
    if method == "univariate":  # eq. (26)
        p = np.prod(ndtr(_standardize(values, var)), axis=0)
    elif method == "bivariate":  # eq. (30)
        p = _both_positive(values[0], var[0], values[2], var[2], cov_g[0, 2]) * _both_positive(
            values[1], var[1], values[3], var[3], cov_g[1, 3]
        )
    else:
        p = positive_orthant_sequential(values, cov_g)
    return np.where(still, 0.0, p)


# Friction conditions of the loading-move events in "must be >= 0" form (Sec. V-A1), as signed
# rows of simulate.friction_functionals: -wL, -wR (stick), wL, wN (slide left), wR (slide right).
_FRICTION_ROWS = np.array([L_, R_, L_, N_, R_])
_FRICTION_SIGNS = np.array([-1.0, -1.0, 1.0, 1.0, 1.0])
# Per event (stick, slide left, slide right): its 6 conditions among the 9 = (7-10) + the above.
_EVENT_PICK = np.array([[0, 1, 2, 3, 4, 5], [0, 1, 2, 3, 6, 7], [0, 1, 2, 3, 8, 7]])
# Contacts whose bound (the least likely of their single conditions) is below this are skipped.
PRUNE_BELOW = 1e-12


def _likely(values: np.ndarray, var: np.ndarray, h_min: float) -> np.ndarray:
    """Whether Phi(values / sd) > PRUNE_BELOW, as the equivalent values >= h_min sd with
    h_min = Phi^-1(PRUNE_BELOW): no division and no Phi. Zero variance: values >= 0."""
    return values >= h_min * np.sqrt(np.maximum(var, 0.0))


def _contact_events_sequential(a, b, shape: GaussianShape, load, means, covs) -> np.ndarray:
    """(3, K, E) P(C_e and K_e / SL_e / SR_e) as one 6-condition orthant each (Sec. V-A1: the
    stick or slip cone adds two linear conditions in t = d - c to (7-10)), by sequential
    conditioning, so the dependence between where the edge lies and how it is tilted is kept.

    Pruning (Sec. IV-F): an event is no likelier than its least likely single condition; events
    where that bound is below ``PRUNE_BELOW`` are set to 0 (error < 1e-12 each). Bounds are
    compared on standardized means (``_likely``). The covariances of the four collision
    conditions with all nine (four collision, five signed friction) are formed once per
    surviving (move, edge) pair, those among the friction conditions once per edge; all
    surviving events go through one batched orthant evaluation that reads its 6 x 6 blocks from
    this pool. ``means``, ``covs``: ``shape.edge_gaussians()``.
    """
    a, b = _move_endpoints(a, b)
    # PRUNE_BELOW <= 0 keeps every event but those with an impossible condition (exactly 0).
    h_min = max(float(ndtri(PRUNE_BELOW)), -1e300) if PRUNE_BELOW > 0 else -1e300
    w = friction_functionals(load, shape.friction)[_FRICTION_ROWS] * _FRICTION_SIGNS[:, None]
    fric_grad = np.concatenate([-w, w], axis=1)  # (5, 4): gradient of w . (d - c) in (c, d)
    fric_mean = (means[:, 2:] - means[:, :2]) @ w.T  # (E, 5)
    fric_cov = fric_grad @ covs @ fric_grad.T  # (E, 5, 5)
    fric_var = np.diagonal(fric_cov, axis1=1, axis2=2)
    event_ok = np.all(_likely(fric_mean, fric_var, h_min)[:, _EVENT_PICK[:, 4:] - 4], axis=2).T
    # Cheap first pass over all (K, E): (III) and (IV) are linear in c resp. d with gradient
    # +-perp(b - a), so their means and variances are (K, 2) x (2, E) and (K, 4) x (4, E) products.
    move = b - a
    perp = geometry2d.perp(move)  # (K, 2)
    along = np.sum(perp * a, axis=1)[:, None]  # perp(move) . a
    outer = (perp[:, :, None] * perp[:, None, :]).reshape(-1, 4)  # (K, 4)
    still = (np.linalg.norm(move, axis=1) == 0.0)[:, None]
    keep = ~still & event_ok.any(axis=0)[None]
    keep &= _likely(perp @ means[:, :2].T - along, outer @ covs[:, :2, :2].reshape(-1, 4).T, h_min)
    keep &= _likely(along - perp @ means[:, 2:].T, outer @ covs[:, 2:, 2:].reshape(-1, 4).T, h_min)
    k_idx, e_idx = np.nonzero(keep)
    # Second pass on the survivors: the covariance of the four collision conditions with all
    # nine, once per pair, and of the friction conditions with each other, once per edge.
    values, grads = _conditions(a[k_idx], b[k_idx], means[e_idx, :2], means[e_idx, 2:])
    count = len(k_idx)
    g9t = np.empty((count, 4, 9))  # gradients of the nine conditions as columns
    g9t[:, :, :4], g9t[:, :, 4:] = np.swapaxes(grads, 1, 2), fric_grad.T
    pool = np.empty(count * 36 + fric_cov.size)  # the pairs' (4, 9) blocks, then fric_cov
    pair = np.matmul(grads @ covs[e_idx], g9t, out=pool[: count * 36].reshape(count, 4, 9))
    pool[count * 36 :] = fric_cov.ravel()
    var = np.diagonal(pair[:, :, :4], axis1=1, axis2=2).T  # (4, M)
    alive = _likely(values, var, h_min).all(axis=0)[None] & event_ok[:, e_idx]  # (3, M)
    slot, pos = np.nonzero(alive)
    pick = np.ascontiguousarray(_EVENT_PICK[slot].T)  # (6, S) rows of each event among the 9
    v9 = np.concatenate([values, fric_mean[e_idx].T])  # (9, M)
    mean6 = np.take(v9, pick * count + pos)  # (6, S)
    del values, grads, g9t, v9  # lower the peak memory of the orthant (fewer page faults)
    # Pool index of entry (i, j) of an event: i < 4: pair[p, i, pick_j]; i >= 4 (friction
    # condition f): pair[p, pick_j, f] if pick_j < 4, else fric_cov[e, f - 4, pick_j - 4].
    at_pair, f = pos * 36, pick[4:]
    at_fric = count * 36 + e_idx[pos] * 25 + (f - 4) * 5 - 4
    rows, at_pair_f = at_pair + np.arange(4)[:, None] * 9, at_pair + f  # entries (i, 0), (j, f)

    def column_at(at, out):
        pick_j = np.take(pick, at)
        np.add(rows, pick_j, out=out[:4])
        np.copyto(out[4:], np.where(pick_j < 4, at_pair_f + 9 * pick_j, at_fric + pick_j))

    var6 = np.take(pool, np.concatenate([rows + np.arange(4)[:, None], at_fric + f]))
    out = np.zeros((3, len(a), len(means)))
    out[slot, k_idx[pos], e_idx[pos]] = _orthant_rows(mean6, var6, pool, column_at)
    return out


def collision_probabilities(a, b, shape: GaussianShape, method: str = "bivariate") -> np.ndarray:
    """(E,) P(C_e): probability that the move a -> b hits edge e (App. B, eq. 26 / 30)."""
    _check_shape(shape)
    means, covs = shape.edge_gaussians()
    return segment_collision_probabilities(a, b, means, covs, method)[0]


def _edge_slip_terms(shape: GaussianShape, load, means, covs) -> dict:
    """Gaussian moments of the edge functionals wL.t, wR.t, wN.t (t = d - c) from the edge
    Gaussians ``means`` (E, 4), ``covs`` (E, 4, 4), and the basis of t for adjacent-edge pairs."""
    w = friction_functionals(load, shape.friction)  # (3, 2)
    grad = np.concatenate([-w, w], axis=1)  # (3, 4): gradient of w . (d - c) in (c, d)
    rows = shape.edge_rows()
    return {
        "mean": (means[:, 2:] - means[:, :2]) @ w.T,  # (E, 3)
        "cov": grad @ covs @ grad.T,  # (E, 3, 3) within an edge
        "w": w,
        "basis_t": shape.basis[rows[:, 2:]] - shape.basis[rows[:, :2]],  # (E, 2, m)
    }


def _vertex_transitions(shape: GaussianShape, terms: dict):
    """Per vertex (n,): continue / stick probabilities after arriving by a left or right slide."""
    n = shape.n_vertices
    _, left, right = edge_index_arrays(n, shape.closed)
    inner = (left >= 0) & (right >= 0)
    el, er = left[inner], right[inner]
    mean, cov, w, basis_t = terms["mean"], terms["cov"], terms["w"], terms["basis_t"]
    # (V, 3, 3): Cov(functional i of l, functional j of r) = w Cov(t_l, t_r) w^T
    cross_cov = w @ (basis_t[el] @ np.swapaxes(basis_t[er], 1, 2)) @ w.T
    # Both slide directions at once: a left slide (row L_) arrives along r(v) = src and goes on
    # to l(v) = dst; a right slide (row R_) the other way round. cov_ds (2V, 3, 3) is
    # Cov(functional i of dst, functional j of src).
    count = len(el)
    src, dst = np.concatenate([er, el]), np.concatenate([el, er])
    row = np.repeat([L_, R_], count)
    face = np.full_like(row, N_)
    cov_ds = np.concatenate([cross_cov, np.swapaxes(cross_cov, 1, 2)])
    at = np.arange(2 * count)
    # The three pair probabilities in one quadrant call: P(slide on dst, slide on src),
    # P(slide on dst, dst faces the load), P(dst faces the load, slide on src).
    e1, i1 = np.concatenate([dst, dst, dst]), np.concatenate([row, row, face])
    e2, i2 = np.concatenate([src, dst, src]), np.concatenate([row, face, row])
    c12 = np.concatenate([cov_ds[at, row, row], cov[dst, row, N_], cov_ds[at, N_, row]])
    p_pair = _both_positive(mean[e1, i1], cov[e1, i1, i1], mean[e2, i2], cov[e2, i2, i2], c12)
    both_slide, dst_slide_faces, faces_after = np.split(p_pair, 3)
    e, i = np.concatenate([src, dst]), np.concatenate([row, row])
    p_src, p_dst = np.split(ndtr(_standardize(mean[e, i], cov[e, i, i])), 2)

    def ratio(num, den):
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(den > 0, np.clip(num / den, 0.0, 1.0), 0.0)

    cont = ratio(both_slide, p_src) * ratio(dst_slide_faces, p_dst)
    stick = np.maximum(ratio(faces_after, p_src) - cont, 0.0)
    out = {k: np.zeros(n) for k in ("cont_left", "stick_left", "cont_right", "stick_right")}
    out["cont_left"][inner], out["cont_right"][inner] = np.split(cont, 2)
    out["stick_left"][inner], out["stick_right"][inner] = np.split(stick, 2)
    return out


def _edge_contact_split(terms: dict) -> np.ndarray:
    """(E, 3) P(K_e | C_e), P(SL_e | C_e), P(SR_e | C_e) from the edge-direction Gaussian."""
    mean, cov = terms["mean"], terms["cov"]
    p_face = ndtr(_standardize(mean[:, N_], cov[:, N_, N_]))
    stick = _both_positive(
        -mean[:, L_], cov[:, L_, L_], -mean[:, R_], cov[:, R_, R_], cov[:, L_, R_]
    )
    sl = _both_positive(mean[:, L_], cov[:, L_, L_], mean[:, N_], cov[:, N_, N_], cov[:, L_, N_])
    sr = _both_positive(mean[:, R_], cov[:, R_, R_], mean[:, N_], cov[:, N_, N_], cov[:, R_, N_])
    split = np.stack([stick, sl, sr], axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        split = np.where(p_face[:, None] > 0, split / p_face[:, None], 0.0)
    total = split.sum(axis=1, keepdims=True)
    return np.where(total > 1.0, split / np.maximum(total, 1e-300), split)


def solve_chain(a: np.ndarray, b: np.ndarray, cyclic: bool) -> np.ndarray:
    """x_f = a_f + b_f x_{f+1} over the last axis (eqs. 21-22 along the feature sequence).

    ``b`` broadcasts against ``a`` (e.g. one coefficient row shared by many right-hand sides).
    Open chains end with x_F = 0; cyclic chains wrap (x_F = x_0) and are solved exactly via
    x_f = y_f + (prod_{i >= f} b_i) x_0. Recursive doubling: O(F log F) vectorized work,
    ceil(log2 F) numpy steps and no Python loop over features.
    """
    b = np.asarray(b, dtype=float)
    shape = np.broadcast_shapes(np.shape(a), b.shape)
    # Features first, so that every doubling step works on contiguous blocks.
    x = np.moveaxis(np.broadcast_to(np.asarray(a, dtype=float), shape), -1, 0).copy()
    prod = np.moveaxis(b, -1, 0).copy()
    size = len(x)
    step = 1
    while step < size:
        x[: size - step] += prod[: size - step] * x[step:]
        prod[: size - step] = prod[: size - step] * prod[step:]
        step *= 2
    x = np.moveaxis(x, 0, -1)
    if cyclic:
        tail = np.cumprod(b[..., ::-1], axis=-1)[..., ::-1]  # prod_{i >= f} b_i
        x0 = x[..., :1] / np.maximum(1.0 - tail[..., :1], 1e-300)
        x = x + tail * x0
    return x


def dock_probabilities(
    shape: GaussianShape,
    starts,
    ends,
    load,
    compliant: bool = True,
    p_clear=None,
    method: str = "sequential",
):
    """Batched eqs. (20-22) for K loading moves ``starts`` -> ``ends`` (K, 2) on one shape.

    Returns p_dock (K,), p_stop_vertex (K, 2, n) (by arrival, as ``DockEstimate``), p_stop_edge
    (K, E); ``p_clear`` (K,) multiplies everything (the prefix's no-contact probability; default 1).
    """
    _check_shape(shape)
    unit(load, "load")
    n = shape.n_vertices
    means, covs = shape.edge_gaussians()
    terms = _edge_slip_terms(shape, load, means, covs)
    if method == "sequential":
        events = _contact_events_sequential(starts, ends, shape, load, means, covs)  # (3, K, E)
    else:
        p_c = segment_collision_probabilities(starts, ends, means, covs, method)  # (K, E)
        events = p_c[None] * _edge_contact_split(terms).T[:, None, :]
    total = events.sum(axis=(0, 2))[None, :, None]
    events /= np.maximum(total, 1.0)  # scaled to sum to 1 where they sum to more
    p_c = events.sum(axis=0)
    stop_edge = events[0]
    stop_vertex = np.zeros((len(p_c), 2, n))
    if compliant:
        trans = _vertex_transitions(shape, terms)
        # Eq. (21) along the edges: a left slide on edge j comes from a contact there or from a
        # left slide on the next edge that continues over their common vertex; mirror image on
        # the right. Both chains go through one solve_chain call (the right one reversed).
        first, last = shape.edges[:, 0], shape.edges[:, 1]
        count = len(p_c)
        chains = solve_chain(
            np.stack([events[1], events[2][:, ::-1]]),  # (2, K, E)
            np.stack([trans["cont_left"][last], trans["cont_right"][first][::-1]])[:, None],
            shape.closed,
        )
        # eq. (20) at vertices: arrive by a left slide from r(v) or a right slide from l(v)
        from_right, from_left = np.zeros((count, n)), np.zeros((count, n))
        from_right[:, first] = chains[0]  # P(L) on r(v)
        from_left[:, last] = chains[1][:, ::-1]  # P(R) on l(v)
        stop_vertex = np.stack(
            [from_right * trans["stick_left"], from_left * trans["stick_right"]], axis=1
        )
    clear = np.ones(len(p_c)) if p_clear is None else np.asarray(p_clear, dtype=float)
    stop_vertex, stop_edge = stop_vertex * clear[:, None, None], stop_edge * clear[:, None]
    p_dock = np.clip(stop_vertex.sum(axis=(1, 2)) + stop_edge.sum(axis=1), 0.0, 1.0)
    return p_dock, stop_vertex, stop_edge


def prefix_clear_probability(shape: GaussianShape, path, method: str = "sequential") -> float:
    """Probability that every move of ``path`` (L, 2) touches nothing: the product over moves of
    1 - sum_e P(C_e) (a move's first contacts are exclusive; moves independent)."""
    path = np.asarray(path, dtype=float)
    if len(path) < 2:
        return 1.0
    means, covs = shape.edge_gaussians()
    p_c = segment_collision_probabilities(path[:-1], path[1:], means, covs, method)
    return float(np.prod(np.clip(1.0 - p_c.sum(axis=1), 0.0, 1.0)))


def dock_probability(
    shape: GaussianShape, path, load, compliant: bool = True, method: str = "sequential"
) -> DockEstimate:
    """P_dock of ``path`` (L >= 2, 2): its last segment is the loading move pushing along ``load``.

    Eqs. (20-22) with the compliant or non-compliant model, times the probability that the
    earlier moves touch nothing.
    """
    _check_shape(shape)
    path = np.asarray(path, dtype=float)
    if path.ndim != 2 or path.shape[1] != 2 or len(path) < 2:
        raise ValueError(f"path must be (L >= 2, 2) waypoints, got shape {path.shape}")
    if not np.all(np.isfinite(path)):
        raise ValueError("path waypoints must be finite")
    clear = prefix_clear_probability(shape, path[:-1], method)
    p_dock, vert, edge = dock_probabilities(
        shape, path[-2:-1], path[-1:], load, compliant, np.array([clear]), method
    )
    return DockEstimate(float(p_dock[0]), vert[0], edge[0], clear)
