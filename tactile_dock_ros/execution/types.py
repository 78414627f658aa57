"""What the executor takes and gives, ROS-free: the docking plane's embedding, a validated plan
and a report (``nodes.convert`` maps them to and from DockingPlan / ExecutionReport)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from tactile_dock_ros.core.history import History

# Tolerance (dimensionless) on |load_direction| = 1 and on plane axis orthonormality.
UNIT_TOLERANCE = 1e-3


@dataclass(frozen=True)
class PlaneFrame:
    """The docking plane in the arm's base frame: origin (3,) metres, orthonormal axes (3,)."""

    origin: np.ndarray
    x_axis: np.ndarray
    y_axis: np.ndarray

    def __post_init__(self) -> None:
        rows = np.array([self.origin, self.x_axis, self.y_axis], dtype=float)
        if rows.shape != (3, 3) or not np.all(np.isfinite(rows)):
            raise ValueError("plane origin and axes must be finite 3-vectors")
        gram = rows[1:] @ rows[1:].T
        if not np.allclose(gram, np.eye(2), atol=UNIT_TOLERANCE):
            raise ValueError(f"plane axes must be orthonormal, got x={rows[1]}, y={rows[2]}")
        for name, value in zip(("origin", "x_axis", "y_axis"), rows, strict=True):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def axes(self) -> np.ndarray:
        """(2, 3): the plane axes as rows."""
        return np.stack([self.x_axis, self.y_axis])

    def point_to_plane(self, p3) -> np.ndarray:
        """Base-frame point(s) (..., 3) -> plane coordinates (..., 2), dropping the normal part."""
        return (np.asarray(p3, float) - self.origin) @ self.axes.T

    def point_from_plane(self, p2) -> np.ndarray:
        return self.origin + np.asarray(p2, float) @ self.axes

    def vector_to_plane(self, v3) -> np.ndarray:
        return np.asarray(v3, float) @ self.axes.T

    def vector_from_plane(self, v2) -> np.ndarray:
        return np.asarray(v2, float) @ self.axes


@dataclass(frozen=True)
class PlanCommand:
    """A validated DockingPlan: waypoints (L, 2) metres, load (2,) unit vector."""

    plan_id: int
    dock: bool
    waypoints: np.ndarray
    load: np.ndarray
    force_threshold: float  # newtons
    max_speed: float  # metres per second
    compliant: bool
    p_dock: float
    objective: float
    target_edge: int
    reason: str
    target_point: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))  # (2,) metres
    episode: int = 0
    history_length: int = 0  # contact_history segments the plan was made on
    nonce: int = 0  # the episode's nonce (EpisodeStatus.nonce); 0: none


class Outcome(Enum):
    """How a plan's execution ended; values equal the ExecutionReport constants."""

    DOCKED = 0
    CONTACT_FAILED = 1
    NO_CONTACT = 2
    ABORTED = 3


# Report.detail of an attempt stopped because no copy of its plan arrived in time.
PRODUCER_LOST = "producer lost:"


@dataclass(frozen=True)
class Report:
    """A validated ExecutionReport: outcome an :class:`Outcome` value, the segments as a
    History, stop point (2,) metres."""

    plan_id: int
    outcome: int
    history: History
    stop_point: np.ndarray
    detail: str
    episode: int = 0
    nonce: int = 0  # the plan's nonce, copied

    @property
    def outcome_name(self) -> str:
        return Outcome(self.outcome).name

    @property
    def producer_lost(self) -> bool:
        """An ABORTED attempt the executor stopped because the planner fell silent: the
        episode goes on when the planner is back (docs/nodes.md, "Restart without loss")."""
        return self.outcome == Outcome.ABORTED.value and self.detail.startswith(PRODUCER_LOST)
