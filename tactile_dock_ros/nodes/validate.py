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
MAX_FORCE_N = 1e5  # |component| of a force (torque: N m): 100x a 6-axis F/T sensor's range
# Posterior samples against the prior they come from (``samples_fit_prior``): a sample is
# A z + mu, so |x_i - mu_i| <= ||A_i|| ||z|| where ||A_i|| is coordinate i's prior std; the norm
# of a standard normal z in m <= MAX_BASIS dimensions exceeds 100 with probability below 1e-1000.
SAMPLE_PRIOR_STDS = 100.0
SAMPLE_PRIOR_SLACK_M = 1e-3  # on top: rounding, and vertices the prior holds fixed (std 0)
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


def within(name: str, values, limit: float, unit: str) -> np.ndarray:
    """``values`` as floats if all are finite with |value| <= ``limit``, else MessageError."""
    array = finite(name, values)
    if np.any(np.abs(array) > limit):
        raise MessageError(f"{name} has a value beyond {limit:g} {unit}")
    return array


def samples_fit_prior(vertices, num_vertices: int, mean, basis) -> None:
    """Reject posterior samples that cannot come from the prior ``mean`` (2n,), ``basis``
    (2n, m): another vertex count (``num_vertices``), or a coordinate further from the prior mean
    than SAMPLE_PRIOR_STDS of its prior std plus SAMPLE_PRIOR_SLACK_M. ``vertices``: (N, n, 2),
    None for an empty set (only the count is checked). Decision: a sample set built on another
    prior (a stale inference, a foreign publisher) or with absurd values (1e150 overflowed the
    probabilistic simulation to P_dock 0) must not reach the planner; any sample the sampler
    can draw from this prior passes."""
    n = len(mean) // 2
    if num_vertices != n:
        raise MessageError(f"samples have {num_vertices} vertices, the prior has {n}")
    if vertices is None or not len(vertices):
        return
    bound = SAMPLE_PRIOR_STDS * np.linalg.norm(basis, axis=1) + SAMPLE_PRIOR_SLACK_M
    with np.errstate(over="ignore", invalid="ignore"):
        excess = np.abs(np.reshape(vertices, (len(vertices), -1)) - mean) / bound
    if not np.all(excess <= 1.0):
        k, i = np.unravel_index(np.argmax(np.nan_to_num(excess, nan=np.inf)), excess.shape)
        raise MessageError(
            f"sample {k} coordinate {i} is {excess[k, i] * bound[i]:.3g} m from the prior mean, "
            f"beyond {SAMPLE_PRIOR_STDS:g} prior std + {SAMPLE_PRIOR_SLACK_M:g} m"
        )


# Serialized size (CDR bytes) a message may have, judged before it is deserialized: room for
# the largest arrays above plus MESSAGE_SLACK_BYTES of scalars and strings. Decision: a message
# of a million waypoints took 2.7-3.7 s to become Python objects on the executor's thread (no
# arm command meanwhile): its length is the one thing checked before any of that work.
MESSAGE_SLACK_BYTES = 64 * 1024
_ARRAY_BYTES = {  # message type name -> bytes of its largest arrays at the limits above
    "DockingPlan": MAX_WAYPOINTS * 24,
    "ExecutionReport": MAX_SEGMENTS * 160,  # a segment: header, two points, status, plan id
    "ContactHistory": MAX_SEGMENTS * 160,
    "ShapeSamples": MAX_VALUES * 8 + MAX_SEGMENTS * 4,
    "ShapeDistribution": 2 * MAX_VALUES * 8 + MAX_VERTICES * 4,
    "EpisodeStatus": MAX_CYCLES * 48,
    "Image": MAX_PIXELS * 4,
}


def max_message_bytes(msg_type) -> int:
    """The largest serialized ``msg_type`` (a message class) a subscription takes."""
    return MESSAGE_SLACK_BYTES + _ARRAY_BYTES.get(msg_type.__name__, 0)


def check_size(what: str, size: int, limit: int) -> None:
    if size > limit:
        raise MessageError(f"{what} is {size} bytes serialized, the limit is {limit}")
