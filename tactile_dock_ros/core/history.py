"""Tactile history H = {(a_i, b_i, s_i)} (paper Sec. III-A3, III-B).

Each observation is a segment the tool point travelled, from ``a`` to ``b`` in the plane, with
what it felt. Status values equal the ``ContactSegment`` message constants.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import IntEnum

import numpy as np

# Contact segments shorter than this (metres) carry no usable direction; they are rejected.
MIN_CONTACT_LENGTH = 1e-9


class Status(IntEnum):
    """Collision status of a history segment (ContactSegment constants)."""

    FREE = 0
    COLLIDE = 1
    STICK = 2
    SLIP_LEFT = 3  # slid counter-clockwise from the motion direction
    SLIP_RIGHT = 4  # slid clockwise from the motion direction


# The one colour (r, g, b, a) per status, for the figures (tools.figures) and the RViz markers
# (nodes.markers) alike: free green, collide red, stick purple, slip left orange, right gold.
STATUS_RGBA = {
    Status.FREE: (0.17, 0.63, 0.17, 1.0),
    Status.COLLIDE: (0.84, 0.15, 0.16, 1.0),
    Status.STICK: (0.58, 0.40, 0.74, 1.0),
    Status.SLIP_LEFT: (1.0, 0.50, 0.05, 1.0),
    Status.SLIP_RIGHT: (1.0, 0.84, 0.0, 1.0),
}


@dataclass(frozen=True)
class History:
    """Immutable batch of observations: ``a``, ``b`` (k, 2) metres, ``status`` (k,).

    Free segments may have zero length (they constrain nothing); contact segments must not,
    since their direction defines the stick/slip cone.
    """

    a: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    b: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    status: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))

    def __post_init__(self) -> None:
        a = np.asarray(self.a, dtype=float).reshape(-1, 2)
        b = np.asarray(self.b, dtype=float).reshape(-1, 2)
        status = np.asarray(self.status, dtype=int).reshape(-1)
        if not len(a) == len(b) == len(status):
            raise ValueError(f"a, b, status lengths differ: {len(a)}, {len(b)}, {len(status)}")
        if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
            raise ValueError("history segment endpoints must be finite")
        valid = set(int(s) for s in Status)
        if bad := sorted(set(status.tolist()) - valid):
            raise ValueError(f"unknown contact status {bad}; expected one of {sorted(valid)}")
        short = (status != Status.FREE) & (np.linalg.norm(b - a, axis=1) < MIN_CONTACT_LENGTH)
        if np.any(short):
            raise ValueError(f"contact segments {np.flatnonzero(short).tolist()} have zero length")
        for name, value in (("a", a), ("b", b), ("status", status)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.status)

    def extend(self, a, b, status) -> History:
        """A new history with the given observations appended."""
        return History(
            np.concatenate([self.a, np.reshape(a, (-1, 2))]),
            np.concatenate([self.b, np.reshape(b, (-1, 2))]),
            np.concatenate([self.status, np.reshape(status, -1)]),
        )

    def subset(self, keep: np.ndarray) -> History:
        """The observations selected by a boolean mask or index array."""
        return History(self.a[keep], self.b[keep], self.status[keep])

    @property
    def is_contact(self) -> np.ndarray:
        """(k,) whether each observation touched the shape (any status but FREE)."""
        return self.status != Status.FREE
