"""Constraint systems in the whitened coordinates z of ``x = A z + mu`` for the samplers.

A system is a list of K primitives g_k(z) (each linear or quadratic in z) plus a rule that turns
their values into per-observation values (feasible iff all <= 0). Along the HMC ellipse
z(t) = z0 cos t + p sin t (eq. 15) every primitive is a trigonometric polynomial
``k0 + k1 cos t + k2 sin t + k3 cos 2t + k4 sin 2t``; along a line z0 + t d it is a quadratic
``q0 + q1 t + q2 t^2`` (Sec. IV-E). The samplers only use this interface, so the same HMC runs
on shape histories and on plain linear inequalities (the Brownian-bridge benchmark).
"""

from __future__ import annotations

import numpy as np

from . import hmc_exit
from .constraints import PairStructure, bilinear, observation_primitives, quad
from .history import History
from .shape import GaussianShape

_QUAD_GRADIENT_SIGN = np.array([-1.0, 1.0, 1.0, -1.0])


def _quad_gradient(y: np.ndarray) -> np.ndarray:
    """Gradient of ``quad`` at y (..., 4)."""
    return y[..., ::-1] * _QUAD_GRADIENT_SIGN


class _TrigSystem:
    """What the HMC loop needs of a system: ``ellipse_terms`` (per chain, small) and the
    static ``window_tables`` (``hmc_exit.tables``) from which the compiled window search
    builds each primitive's trig coefficients; here the same coefficients as arrays."""

    def ellipse_coefficients(self, z0: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Trig coefficients (C, 5, K) of each primitive along mu + A(z0 cos t + p sin t)."""
        terms = self.ellipse_terms(z0, p)
        return hmc_exit.coefficients(*terms, self.window_tables, self.exit_structure)


class HistoryConstraints(_TrigSystem):
    """f_H restricted to (observation, edge) ``pairs`` (eqs. 1-3, 16-17) as a function of z."""

    def __init__(self, shape: GaussianShape, history: History, pairs: np.ndarray):
        self.shape = shape
        self.history = history
        self.structure = PairStructure(history.status, pairs)
        pairs = self.structure.pairs
        sign, lin, const, active = observation_primitives(history, shape.friction)
        obs = pairs[:, 0]
        rows = shape.edge_rows()[pairs[:, 1]]  # (P, 4) indices into x
        self.n_dim = shape.n_basis
        self.n_obs = len(history)
        self.n_pairs = len(pairs)
        self._rows = rows
        self._mean_y = shape.mean[rows]  # (P, 4)
        self._sign, self._lin, self._const = sign[obs], lin[obs], const[obs]
        self._active = active[obs]
        # slot-major order: slot j's primitives are one contiguous block (fast pair reductions)
        self.prim_slot, self.prim_pair = np.nonzero(self._active.T)
        self._cone = np.flatnonzero(self._active[:, 4])  # pairs with g5, g6
        self.linear = self._sign[self.prim_pair, self.prim_slot] == 0
        self.n_prims = len(self.prim_pair)
        self._prim_index = np.full((self.n_pairs, 6), -1)
        self._prim_index[self.prim_pair, self.prim_slot] = np.arange(self.n_prims)
        # for the compiled kernels (``hmc_exit.window_exits``, ``descent_scan``): each pair's
        # primitive per slot (-1 inactive), its observation (sorted), free pairs, contacts
        self.exit_structure = hmc_exit.structure(
            self._prim_index, pairs[:, 0], self.structure.free_pair, ~self.structure.free_obs, False
        )
        # flat per-primitive coefficients (K,), (K, 4), (K,)
        self._psign = self._sign[self.prim_pair, self.prim_slot]
        self._plin = self._lin[self.prim_pair, self.prim_slot]
        self._pconst = self._const[self.prim_pair, self.prim_slot]
        # g_k(z) = g_mean + L_k . z + s_k quad(A_k z): only g1 (sign -1) and g2 (sign +1) are
        # quadratic, and they are the first two slot blocks (pairs 0..P-1 each)
        mean_y = self._mean_y[self.prim_pair]
        grad_mean = self._psign[:, None] * _quad_gradient(mean_y) + self._plin  # (K, 4)
        self._g_mean = self._psign * quad(mean_y) + np.sum(self._plin * mean_y, -1) + self._pconst
        pair_basis = shape.basis[rows]  # (P, 4, m)
        self._lin_z = np.einsum("kj,kjm->mk", grad_mean, pair_basis[self.prim_pair]).copy()
        # the quadratic term depends on the pair's edge only: computed once per paired edge
        # (tens of edges against hundreds of pairs), then gathered to the pairs
        edges, self._pair_edge = np.unique(pairs[:, 1], return_inverse=True)
        self.n_edges = len(edges)
        edge_basis = shape.basis[shape.edge_rows()[edges]]  # (E, 4, m)
        # (m, 4E) coordinate-major: each edge coordinate of ``_y`` is one contiguous plane
        self._edge_basis = np.ascontiguousarray(edge_basis.T.reshape(self.n_dim, -1))
        # L_k . z = grad_mean_k . (edge coordinates of A z): 4 terms per primitive, not m
        prim_edge = self._pair_edge[self.prim_pair]
        self.window_tables = hmc_exit.tables(
            grad_mean, prim_edge, self._g_mean, self._psign, prim_edge, self._prim_index
        )

    def _y(self, z: np.ndarray) -> np.ndarray:
        """Displacements A z of the paired edges' end coordinates, (..., E, 4) (a view of
        (..., 4, E)); ``[..., self._pair_edge]`` of a per-edge value gives the pairs'."""
        y = (z @ self._edge_basis).reshape(*z.shape[:-1], 4, self.n_edges)
        return np.moveaxis(y, -2, -1)

    def _with_quadratic(self, lin: np.ndarray, q: np.ndarray) -> np.ndarray:
        """Per-primitive values (..., K): ``lin`` (modified in place) plus the per-pair
        quadratic term ``q`` (..., P) with sign -1 for g1 and +1 for g2."""
        p = self.n_pairs
        lin[..., :p] -= q
        lin[..., p : 2 * p] += q
        return lin

    def values(self, z: np.ndarray) -> np.ndarray:
        """Primitive values (..., K) at states z (..., m)."""
        q = quad(self._y(z))[..., self._pair_edge]
        return self._with_quadratic(z @ self._lin_z + self._g_mean, q)

    def primitive_index(self, pair: np.ndarray, slot: int) -> np.ndarray:
        """Flat primitive indices of slot ``slot`` (0..5 for g1..g6) of the given pairs."""
        return self._prim_index[pair, slot]

    def pair_values_of(self, g: np.ndarray) -> np.ndarray:
        """Per-pair values (..., P) from primitive values (..., K)."""
        p, nc = self.n_pairs, len(self._cone)
        g1, g2, g3, g4 = (g[..., j * p : (j + 1) * p] for j in range(4))
        gmax = np.maximum(np.maximum(g1, g2), np.maximum(g3, g4))
        gmin = np.minimum(np.minimum(g1, g2), np.minimum(g3, g4))
        if nc:
            cone = np.maximum(g[..., 4 * p : 4 * p + nc], g[..., 4 * p + nc :])
            gmax[..., self._cone] = np.maximum(gmax[..., self._cone], cone)
        return np.where(self.structure.free_pair, np.maximum(-gmax, gmin), gmax)

    def reduce_pairs(self, pair: np.ndarray) -> np.ndarray:
        """Per-observation values (..., n_obs) from per-pair values (..., P)."""
        return self.structure.reduce_pairs(pair)

    def violations(self, g: np.ndarray) -> np.ndarray:
        """Per-observation values (..., n_obs) from primitive values (..., K)."""
        return self.reduce_pairs(self.pair_values_of(g))

    def steepest_primitive(
        self, values: np.ndarray, obs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """For each row of primitive values (C, K) (``values`` at states z), the primitive k
        and sign s with f_obs(z) = s g_k(z) locally (the active branch of the max/min
        structure); used as a descent direction."""
        pv = self.pair_values_of(values)  # (C, P)
        in_obs = self.structure.pairs[:, 0][None] == np.asarray(obs)[:, None]
        free = self.structure.free_obs[obs]
        # free observations: the worst pair (max); contact: the best pair (min)
        key = np.where(in_obs, np.where(free[:, None], -pv, pv), np.inf)
        pair = np.argmin(key, axis=1)
        slot_prims = self._prim_index[pair]  # (C, 6)
        rows = np.arange(len(values))[:, None]
        g = np.where(slot_prims >= 0, values[rows, np.maximum(slot_prims, 0)], -np.inf)
        g4 = g[:, :4]
        enter_branch = -g4.max(axis=1) >= g4.min(axis=1)  # all g <= 0: raise the largest
        slot = np.where(
            free, np.where(enter_branch, g4.argmax(axis=1), g4.argmin(axis=1)), g.argmax(axis=1)
        )
        sign = np.where(free & enter_branch, -1.0, 1.0)
        prim = self._prim_index[pair, slot]
        return prim, sign

    def pair_violations(self, z: np.ndarray) -> np.ndarray:
        """Per-pair values (..., P) at states z (see ``PairStructure.pair_values``)."""
        return self.pair_values_of(self.values(z))

    def ellipse_terms(self, z0: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The paired edges' end displacements A z0 and A p along mu + A(z0 cos t + p sin t),
        (C, E, 4) each: all ``hmc_exit`` needs of a chain (see ``window_tables``)."""
        c = len(z0)
        y = np.ascontiguousarray(self._y(np.concatenate([z0, p])))
        return y[:c], y[c:]

    def line_coefficients(self, z0: np.ndarray, d: np.ndarray) -> np.ndarray:
        """Polynomial coefficients (C, K, 3) of each primitive along mu + A(z0 + t d)."""
        y0, v = self._y(z0), self._y(d)
        out = np.zeros((len(z0), self.n_prims, 3))
        out[..., 0] = self.values(z0)
        pe = self._pair_edge
        out[..., 1] = self._with_quadratic(d @ self._lin_z, 2 * bilinear(y0, v)[..., pe])
        self._with_quadratic(out[..., 2], quad(v)[..., pe])
        return out

    def gradient(self, z: np.ndarray, prim: np.ndarray) -> np.ndarray:
        """Gradients (C, m) of primitive ``prim[c]`` at state ``z[c]``."""
        rows = self.shape.basis[self._rows[self.prim_pair[prim]]]  # (C, 4, m)
        y = np.matmul(rows, z[:, :, None])[..., 0]
        quad_part = np.matmul(_quad_gradient(y)[:, None], rows)[:, 0]
        return self._lin_z[:, prim].T + self._psign[prim, None] * quad_part


class LinearConstraints(_TrigSystem):
    """Plain linear inequalities F z + h <= 0, each its own observation."""

    def __init__(self, F: np.ndarray, h: np.ndarray):
        self.F = np.asarray(F, dtype=float)
        self.h = np.asarray(h, dtype=float).reshape(-1)
        if self.F.ndim != 2 or len(self.F) != len(self.h):
            raise ValueError(f"F (K, m) and h (K,) mismatch: {self.F.shape}, {self.h.shape}")
        self.n_prims, self.n_dim = self.F.shape
        self.n_obs = self.n_prims
        self.linear = np.ones(self.n_prims, dtype=bool)
        self.n_pairs = self.n_prims  # each inequality is its own pair and observation
        self.n_edges = self.n_prims  # and its own "edge" (``ellipse_terms``: F_k . z)
        each = np.arange(self.n_prims)  # its own pair and observation, free: violated where > 0
        self.exit_structure = hmc_exit.structure(
            each[:, None], each, np.ones(self.n_prims), np.zeros(self.n_obs), True
        )
        k = self.n_prims  # k1 = F_k . z: one "edge" per primitive, no quadratic term
        self.window_tables = hmc_exit.tables(
            np.ones((k, 1)), np.arange(k), self.h, np.zeros(k), np.zeros(k), each[:, None]
        )

    def values(self, z: np.ndarray) -> np.ndarray:
        return z @ self.F.T + self.h

    def violations(self, g: np.ndarray) -> np.ndarray:
        return g

    def ellipse_terms(self, z0: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return (z0 @ self.F.T)[..., None], (p @ self.F.T)[..., None]

    def line_coefficients(self, z0: np.ndarray, d: np.ndarray) -> np.ndarray:
        return np.stack(
            [z0 @ self.F.T + self.h, d @ self.F.T, np.zeros((len(z0), self.n_prims))], axis=-1
        )

    def steepest_primitive(
        self, values: np.ndarray, obs: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(obs), np.ones(len(obs))

    def gradient(self, z: np.ndarray, prim: np.ndarray) -> np.ndarray:
        return self.F[prim]
