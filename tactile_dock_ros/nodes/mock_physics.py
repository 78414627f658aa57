"""Time-stepped point tool against a ground-truth polyline: compliance and Coulomb friction.

The mock arm tracks the commanded Cartesian velocity with a setpoint ``s`` (integrated each
step) and a stiff linear spring (``stiffness`` N/m) between ``s`` and the tool point ``p``. The
tool never enters the solid: it moves to ``s`` if that is free, else stops at the first surface
point ``h`` on the way. There the spring push f = k (s - h) splits into a normal part f_n
(into the surface) and a tangential part f_t; Coulomb friction holds the tool while
|f_t| <= mu f_n (stick), otherwise it slides along the edge until |f_t| = mu f_n (quasi-static
slip), clamped to the edge and stopped by any other edge on the way. This is the compliant
motion model of the paper (Sec. V-A) made time-stepped. Edges are oriented as in
``core.shape``: walking c -> d the solid is on the left, the outward normal on the right.
The measured force is the environment's force on the tool, k (p - s), zero in free space.
"""

from __future__ import annotations

import numpy as np

_EPS = 1e-9  # slack on segment parameters, dimensionless


class PointToolSim:
    """Quasi-static simulation of a point tool; positions in metres, forces in newtons."""

    def __init__(self, vertices, closed: bool, friction: float, stiffness: float, start) -> None:
        v = np.asarray(vertices, float)
        if v.ndim != 2 or v.shape[1] != 2 or len(v) < 2 or not np.all(np.isfinite(v)):
            raise ValueError("vertices must be a finite (n >= 2, 2) array")
        if friction < 0 or stiffness <= 0:
            raise ValueError("friction must be >= 0 and stiffness > 0")
        idx = np.arange(len(v) if closed else len(v) - 1)
        self.c, self.d = v[idx], v[(idx + 1) % len(v)]
        length = np.linalg.norm(self.d - self.c, axis=1)
        keep = length > 0
        self.c, self.d, length = self.c[keep], self.d[keep], length[keep]
        self.tangent = (self.d - self.c) / length[:, None]
        self.normal = np.stack([self.tangent[:, 1], -self.tangent[:, 0]], axis=1)
        self.friction, self.stiffness = float(friction), float(stiffness)
        self.tool = np.asarray(start, float).copy()
        self.setpoint = self.tool.copy()
        self.contact_edge: int | None = None

    @property
    def force(self) -> np.ndarray:
        """Environment force on the tool (2,) N: zero in free space."""
        return self.stiffness * (self.tool - self.setpoint)

    def _first_hit(self, p: np.ndarray, q: np.ndarray, skip: int | None = None):
        """Earliest edge entered along p -> q: (edge index, point) or (None, None)."""
        r = q - p
        e = self.d - self.c
        denom = r[0] * e[:, 1] - r[1] * e[:, 0]
        w = self.c - p
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (w[:, 0] * e[:, 1] - w[:, 1] * e[:, 0]) / denom
            u = (w[:, 0] * r[1] - w[:, 1] * r[0]) / denom
        entering = (self.normal @ r) < 0
        ok = entering & (np.abs(denom) > 1e-15) & (t >= -_EPS) & (t <= 1 + _EPS)
        ok &= (u >= -_EPS) & (u <= 1 + _EPS)
        if skip is not None:
            ok[skip] = False
        if not ok.any():
            return None, None
        i = int(np.flatnonzero(ok)[np.argmin(t[ok])])
        return i, p + max(t[i], 0.0) * r

    def step(self, velocity, dt: float) -> None:
        """Advance the setpoint by velocity (2,) m/s over dt seconds and resolve the tool."""
        self.setpoint = self.setpoint + np.asarray(velocity, float) * dt
        edge, hit = self._first_hit(self.tool, self.setpoint)
        self.contact_edge = edge
        if edge is None:
            self.tool = self.setpoint.copy()
            return
        push = self.stiffness * (self.setpoint - hit)
        f_n = -float(push @ self.normal[edge])
        f_t = float(push @ self.tangent[edge])
        excess = abs(f_t) - self.friction * f_n
        if excess <= 0:
            self.tool = hit
            return
        along = float((hit - self.c[edge]) @ self.tangent[edge])
        length = float(np.linalg.norm(self.d[edge] - self.c[edge]))
        target_along = np.clip(along + np.sign(f_t) * excess / self.stiffness, 0.0, length)
        slid = self.c[edge] + target_along * self.tangent[edge]
        other, blocked = self._first_hit(hit, slid, skip=edge)
        self.tool = slid if other is None else blocked
