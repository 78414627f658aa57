"""Time-stepped point tool against a ground-truth polyline: compliance and Coulomb friction.

The mock arm tracks the commanded Cartesian velocity with a setpoint ``s`` (integrated each
step) and a linear spring between ``s`` and the tool point ``p`` with stiffness ``stiffness``
(N/m) along the current motion direction d (the last non-zero command) and
``lateral_stiffness`` across it: K = k d d^T + k_lat (I - d d^T). A small k_lat is the paper's
arm that is compliant perpendicular to the motion (Sec. III-A2); k_lat = k is isotropic.
The tool never enters the solid: it moves to ``s`` if that is free, else stops at the first
surface point ``h`` on the way. There the push f = K (s - h) splits into a normal part f_n (into
the surface) and a tangential part f_t; Coulomb friction holds the tool while
|f_t| <= mu f_n (stick), otherwise it slides along the edge to where |f_t| = mu f_n
(quasi-static slip, solved in closed form for the linear spring), at most ``max_slide_speed``
per second, clamped to the edge and stopped by any other edge on the way. Edges are oriented as
in ``core.shape``: walking c -> d the solid is on the left, the outward normal on the right.
The measured force is the environment's force on the tool, -K (s - p), zero in free space.

Decision: whenever the commanded direction changes, the setpoint is re-anchored so that the
force stays continuous (bumpless transfer, as an impedance controller switching its stiffness
does): the stiffness axes follow the command, the force does not jump with them. Without it a
deflection built up across the motion under the weak lateral spring became a push along the
stiff new direction at once: after a slide and the executor's retreat, 4 cm at 25 N/m (1.3 N)
turned into 19 N in one step (``test_a_new_motion_direction_keeps_the_contact_force_continuous``).
Until 2026-11-26 only turns above 30 degrees re-anchored (not reversals, not steering within a
move), but any turn of the stiff axis under a deflection jumps the force (4 cm: 1.3 N -> 5.9 N
for a 20 degree steer): in the node suite the executor's release along the measured force after
a retreat (16 degrees off the reverse of a move the tool had slid along) stopped at once with
the force "grown" (3 -> 7 -> 15 N in two 5 ms steps in the in-process replay of those plans),
the tool stayed wedged against the face, and the planner gave up on feasible truths ("the tool
is inside the likely-obstacle region with no way out": three_ledges seed 1, notch seed 4). An
unchanged direction keeps the setpoint (re-anchoring would give the same one).
"""

from __future__ import annotations

import numpy as np

from tactile_dock_ros.core.geometry2d import cross, outward_normal

_EPS = 1e-9  # slack on segment parameters, dimensionless


class PointToolSim:
    """Quasi-static simulation of a point tool; positions in metres, forces in newtons."""

    def __init__(
        self,
        vertices,
        closed: bool,
        friction: float,
        stiffness: float,
        start,
        lateral_stiffness: float | None = None,
        max_slide_speed: float = np.inf,
    ) -> None:
        v = np.asarray(vertices, float)
        if v.ndim != 2 or v.shape[1] != 2 or len(v) < 2 or not np.all(np.isfinite(v)):
            raise ValueError("vertices must be a finite (n >= 2, 2) array")
        lateral = stiffness if lateral_stiffness is None else lateral_stiffness
        if friction < 0 or stiffness <= 0 or not 0 < lateral <= stiffness or max_slide_speed <= 0:
            raise ValueError(
                "need friction >= 0, stiffness > 0, 0 < lateral_stiffness <= stiffness and "
                "max_slide_speed > 0"
            )
        self.closed = bool(closed)
        idx = np.arange(len(v) if closed else len(v) - 1)
        self.c, self.d = v[idx], v[(idx + 1) % len(v)]
        length = np.linalg.norm(self.d - self.c, axis=1)
        keep = length > 0
        self.c, self.d, length = self.c[keep], self.d[keep], length[keep]
        self.tangent = (self.d - self.c) / length[:, None]
        self.normal = outward_normal(self.tangent)
        self.friction, self.stiffness, self.lateral = float(friction), float(stiffness), lateral
        self.max_slide_speed = float(max_slide_speed)
        self.direction = np.array([1.0, 0.0])
        self.tool = np.asarray(start, float).copy()
        self.setpoint = self.tool.copy()
        self.contact_edge: int | None = None

    @property
    def stiffness_matrix(self) -> np.ndarray:
        """K (2, 2) N/m for the current motion direction."""
        dd = np.outer(self.direction, self.direction)
        return self.stiffness * dd + self.lateral * (np.eye(2) - dd)

    @property
    def force(self) -> np.ndarray:
        """Environment force on the tool (2,) N: zero in free space."""
        return self.stiffness_matrix @ (self.tool - self.setpoint)

    def _hits(self, p: np.ndarray, q: np.ndarray, skip=()):
        """Edges entered first along p -> q (ties at a shared vertex), and the point.

        Returns (indices array, point) or (empty, None) when p -> q is free.
        """
        r = q - p
        e = self.d - self.c
        denom = cross(r, e)
        w = self.c - p
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            t = cross(w, e) / denom
            u = cross(w, r) / denom
        entering = (self.normal @ r) < 0
        ok = entering & (np.abs(denom) > 1e-15) & (t >= -_EPS) & (t <= 1 + _EPS)
        ok &= (u >= -_EPS) & (u <= 1 + _EPS)
        ok[list(skip)] = False
        if not ok.any():
            return np.zeros(0, int), None
        first = t[ok].min()
        ties = np.flatnonzero(ok & (t <= first + _EPS))
        return ties, p + max(first, 0.0) * r

    def _slide_range(self, edge: int, length: float) -> tuple[float, float]:
        """Where a slide along ``edge`` may end: its vertices, except an open polyline's first
        and last vertex, off which the tool slides free."""
        low = -np.inf if edge == 0 and not self.closed else 0.0
        high = np.inf if edge == len(self.c) - 1 and not self.closed else length
        return low, high

    def step(self, velocity, dt: float) -> None:
        """Advance the setpoint by velocity (2,) m/s over dt seconds and resolve the tool."""
        velocity = np.asarray(velocity, float)
        speed = float(np.linalg.norm(velocity))
        if speed > 0 and not np.allclose(velocity / speed, self.direction, rtol=0.0, atol=1e-12):
            force = self.force
            self.direction = velocity / speed
            self.setpoint = self.tool - np.linalg.solve(self.stiffness_matrix, force)  # bumpless
        self.setpoint = self.setpoint + velocity * dt
        edges, hit = self._hits(self.tool, self.setpoint)
        self.contact_edge = int(edges[0]) if len(edges) else None
        if hit is None:
            self.tool = self.setpoint.copy()
            return
        K = self.stiffness_matrix
        push = K @ (self.setpoint - hit)
        slides = []
        for edge in edges:  # one edge, or the two edges meeting at a vertex
            t, n = self.tangent[edge], self.normal[edge]
            f_n, f_t = -float(push @ n), float(push @ t)
            excess = abs(f_t) - self.friction * f_n
            if excess <= 0:  # held by friction on this edge
                self.tool = hit
                return
            # Sliding by delta along sign(f_t) t: |f_t| falls by a delta, f_n grows by sign c delta.
            sign = np.sign(f_t)
            rate = float(t @ K @ t) + self.friction * sign * float(n @ K @ t)
            delta = min(excess / rate if rate > 0 else np.inf, self.max_slide_speed * dt)
            along = float((hit - self.c[edge]) @ t)
            length = float(np.linalg.norm(self.d[edge] - self.c[edge]))
            target = np.clip(along + sign * delta, *self._slide_range(edge, length))
            slides.append((abs(target - along), self.c[edge] + target * t, edge))
        _, slid, edge = max(slides, key=lambda item: item[0])  # the edge the tool can slide on
        _, blocked = self._hits(hit, slid, skip=edges)  # edges meeting at hit do not block
        self.tool = slid if blocked is None else blocked


def limit_command(velocity, position, dt: float, max_speed: float, box_min, box_max):
    """The arm's own limits on a commanded velocity (2,) m/s at ``position`` (2,) m, as a real
    driver enforces them whatever its commander sends (ros2_control joint limits, moveit_servo's
    velocity scaling and position limits): the speed is scaled down to ``max_speed`` (direction
    kept), then each axis is cut so that one step of ``dt`` s ends inside the box ``box_min`` ..
    ``box_max``; outside the box, motion further out is zeroed and motion back in is kept.
    Returns (velocity, reasons it was changed: empty when untouched)."""
    velocity = np.asarray(velocity, float)
    position = np.asarray(position, float)
    reasons = []
    speed = float(np.linalg.norm(velocity))
    if speed > max_speed:
        velocity = velocity * (max_speed / speed)
        reasons.append(f"speed {speed:.3g} m/s above {max_speed:g}")
    upper = np.maximum((np.asarray(box_max, float) - position) / dt, 0.0)
    lower = np.minimum((np.asarray(box_min, float) - position) / dt, 0.0)
    clipped = np.clip(velocity, lower, upper)
    if not np.array_equal(clipped, velocity):
        reasons.append(f"leaving the workspace box at {np.round(position, 3).tolist()}")
    return clipped, reasons
