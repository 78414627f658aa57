"""Checks every incoming message passes before a node reads it (used by ``convert`` and the
subscription guard of ``common.subscribe``).

A failed check raises :class:`MessageError`, the one exception type of malformed input: the
guard logs it (throttled per cause) and drops the message. Array sizes are bounded here, from
the lengths alone, before anything is allocated for them.
"""

from __future__ import annotations

import re

import numpy as np

# Sizes of the message contract (well above any real use: the benchmark shapes have < 100
# vertices, inference at most 100000 samples, an episode a few hundred contact segments).
MAX_VERTICES = 1_000  # ShapeDistribution / ShapeSamples num_vertices
MAX_BASIS = 1_000  # ShapeDistribution num_basis
MAX_SAMPLES = 100_000  # ShapeSamples num_samples
MAX_VALUES = 10_000_000  # floats in one array field (80 MB)
MAX_SEGMENTS = 100_000  # contact segments in a history or report
MAX_WAYPOINTS = 1_000  # DockingPlan waypoints
MAX_CYCLES = 1_000  # EpisodeStatus cycles (the planner's max_cycles is at most 1000)
MAX_PIXELS = 4096 * 4096  # depth image width * height
MAX_COORDINATE_M = 1e6  # |x|, |y| of a plane point: far beyond any reach, far from overflow
# A stamp further ahead of the receiving node's clock than this is a clock fault (seconds).
MAX_STAMP_LEAD_S = 5.0


class MessageError(ValueError):
    """A message that cannot be converted; the text names the offending field."""


def finite(name: str, values) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if not np.all(np.isfinite(array)):
        raise MessageError(f"{name} holds NaN or inf")
    return array


def bounded(name: str, count: int, limit: int) -> int:
    """``count`` (a length or size field) if 0 <= count <= limit, else MessageError."""
    count = int(count)
    if not 0 <= count <= limit:
        raise MessageError(f"{name} is {count}, the limit is {limit}")
    return count


def check_frame(what: str, msg, frame_id: str) -> None:
    """Reject a stamped message in another frame than ``frame_id`` (tf2 is not used here: the
    publisher must express it there). An empty frame_id is taken to mean ``frame_id``."""
    if msg.header.frame_id and msg.header.frame_id != frame_id:
        raise MessageError(f"{what} is in frame {msg.header.frame_id!r}, expected {frame_id!r}")


def check_stamp(what: str, stamp, now_ns: int) -> None:
    """Reject an invalid builtin_interfaces/Time or one more than MAX_STAMP_LEAD_S ahead of the
    node clock ``now_ns`` (skipped while a simulated clock is still 0). Old stamps are fine: a
    latched prior may be hours old; sensor freshness is judged on the receive time."""
    if stamp.sec < 0 or not 0 <= stamp.nanosec < 1_000_000_000:
        raise MessageError(f"{what} stamp ({stamp.sec} s, {stamp.nanosec} ns) is not a time")
    lead = (stamp.sec * 1_000_000_000 + stamp.nanosec - now_ns) * 1e-9
    if now_ns > 0 and lead > MAX_STAMP_LEAD_S:
        raise MessageError(f"{what} stamp is {lead:.3g} s ahead of the node clock")


_VALUE = re.compile(r"'[^']*'|\[[^\]]*\]|\([^)]*\)|[-+]?(?:\d+\.?\d*|\.\d+)(?:e[-+]?\d+)?|nan|inf")


def cause(err: Exception) -> str:
    """The text of ``err`` with its values (numbers, quoted strings, lists) masked: messages
    that fail the same check for different values share a cause (throttled logging)."""
    return _VALUE.sub("#", str(err))
