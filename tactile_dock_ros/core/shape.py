"""Gaussian polyline shape model ``x = A z + mu``, ``z ~ N(0, I_m)`` (paper Sec. III-A1).

A state ``x`` stacks the ``n`` vertices as ``(x_1, y_1, ..., x_n, y_n)``. Edges join consecutive
vertices (and the last to the first when the shape is ``closed``) and are oriented
counter-clockwise around the solid: walking along an edge the solid is on the left and the
outward normal points right. An open polyline is a terrain profile whose solid lies on the left
of the walking direction (for a floor seen from above, vertices go right to left).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class GaussianShape:
    """Prior or posterior Gaussian over polyline vertices.

    Attributes:
        mean: (2n,) mean state, metres.
        basis: (2n, m) matrix A; covariance = A A^T (m may be 0).
        closed: whether edge (n-1, 0) exists.
        friction: Coulomb friction coefficient of the surface.
        closure_edges: indices of edges that only close an open profile past what the sensor
            saw (perception's tails, ``terrain_prior.add_tails``): no measured surface, so no
            docking site (``planner.holding_frequencies``). Sorted, unique, in [0, E).
    """

    mean: np.ndarray
    basis: np.ndarray
    closed: bool = False
    friction: float = 0.5
    closure_edges: tuple[int, ...] = ()
    edges: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        mean = np.asarray(self.mean, dtype=float)
        if mean.ndim != 1 or mean.size < 4 or mean.size % 2:
            raise ValueError(f"mean must hold 2n >= 4 coordinates, got shape {mean.shape}")
        basis = np.asarray(self.basis, dtype=float).reshape(mean.size, -1)
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(basis))):
            raise ValueError("mean and basis must be finite")
        if not np.isfinite(self.friction) or self.friction < 0:
            raise ValueError(f"friction must be finite and >= 0, got {self.friction}")
        n = mean.size // 2
        if self.closed and n < 3:
            raise ValueError("a closed shape needs at least 3 vertices")
        first = np.arange(n if self.closed else n - 1)
        edges = np.stack([first, (first + 1) % n], axis=1)
        closure = tuple(int(e) for e in np.unique(np.asarray(self.closure_edges, dtype=int)))
        if closure and not (0 <= closure[0] and closure[-1] < len(edges)):
            raise ValueError(f"closure_edges must lie in [0, {len(edges)}), got {closure}")
        object.__setattr__(self, "closure_edges", closure)
        for name, value in (("mean", mean), ("basis", basis), ("edges", edges)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_vertices(self) -> int:
        return self.mean.size // 2

    @property
    def n_basis(self) -> int:
        return self.basis.shape[1]

    @property
    def n_edges(self) -> int:
        return len(self.edges)

    @property
    def mean_vertices(self) -> np.ndarray:
        """(n, 2) mean vertex positions."""
        return self.mean.reshape(-1, 2)

    def states(self, z: np.ndarray) -> np.ndarray:
        """States ``A z + mu`` for ``z`` of shape (..., m); returns (..., 2n)."""
        return np.asarray(z, dtype=float) @ self.basis.T + self.mean

    def vertices(self, z: np.ndarray) -> np.ndarray:
        """Vertex positions for ``z`` of shape (..., m); returns (..., n, 2)."""
        x = self.states(z)
        return x.reshape(*x.shape[:-1], self.n_vertices, 2)

    def sample_z(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` prior draws of z, shape (count, m)."""
        return rng.standard_normal((count, self.n_basis))

    def edge_rows(self) -> np.ndarray:
        """(E, 4) indices into x of each edge's (c_x, c_y, d_x, d_y)."""
        u, v = self.edges[:, 0], self.edges[:, 1]
        return np.stack([2 * u, 2 * u + 1, 2 * v, 2 * v + 1], axis=1)

    def edge_gaussians(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-edge 4-D Gaussian of (c, d): means (E, 4) and covariances (E, 4, 4)."""
        rows = self.edge_rows()
        a_edge = self.basis[rows]  # (E, 4, m)
        return self.mean[rows], a_edge @ np.swapaxes(a_edge, 1, 2)

    def with_mean_basis(self, mean: np.ndarray, basis: np.ndarray) -> GaussianShape:
        """Same topology, friction and closure edges, new Gaussian (e.g. a posterior moment
        fit)."""
        return GaussianShape(mean, basis, self.closed, self.friction, self.closure_edges)

    @classmethod
    def from_samples(cls, samples: np.ndarray, closed: bool, friction: float) -> GaussianShape:
        """Moment fit to vertex samples (N, n, 2): mean and A = centered^T / sqrt(N - 1).

        The basis has N columns (rank <= N - 1); probabilistic simulation only needs A A^T.
        """
        x = np.asarray(samples, dtype=float).reshape(len(samples), -1)
        if len(x) < 2:
            raise ValueError("a moment fit needs at least 2 samples")
        mean = x.mean(axis=0)
        return cls(mean, (x - mean).T / np.sqrt(len(x) - 1), closed, friction)
