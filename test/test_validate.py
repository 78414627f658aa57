"""Validation of incoming messages: any field values either convert to finite,
in-contract data or raise MessageError, never another exception; the drop log is throttled per
cause; every subscription of every node goes through the guard (``common.subscribe``)."""

import re
import warnings

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from conftest import REPO_ROOT
from geometry_msgs.msg import Point, Vector3
from hypothesis import given, settings
from hypothesis import strategies as st
from sensor_msgs.msg import CameraInfo, Image
from std_msgs.msg import Header
from tactile_dock_ros.msg import (
    ContactSegment,
    DockingPlan,
    EpisodeCycle,
    EpisodeStatus,
    ExecutionReport,
    ShapeDistribution,
    ShapeSamples,
)

from tactile_dock_ros.nodes import convert, validate
from tactile_dock_ros.nodes.common import MalformedLog
from tactile_dock_ros.nodes.validate import MessageError

FLOATS = st.floats(allow_nan=True, allow_infinity=True)
SMALL = st.floats(-2.0, 2.0) | FLOATS
EXAMPLES = settings(max_examples=100, deadline=None)
# garbage in gets a MessageError, never a numpy overflow warning on the way
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def _convert(fn, *args):
    """fn(*args), or None when it raised MessageError; any other exception fails the test."""
    try:
        return fn(*args)
    except MessageError:
        return None


def _floats(data, count):
    """Exactly ``count`` values, or a list of another length."""
    return data.draw(st.lists(SMALL, min_size=count, max_size=count) | st.lists(SMALL, max_size=9))


@EXAMPLES
@given(st.data(), st.integers(0, 6), st.integers(0, 3), FLOATS | st.floats(0.0, 1.0))
def test_shape_distribution(data, n, m, friction):
    msg = ShapeDistribution(num_vertices=n, num_basis=m, mean=_floats(data, 2 * n),
                            basis=_floats(data, 2 * n * m), friction=friction)  # fmt: skip
    shape = _convert(convert.shape_from_msg, msg)
    if shape is not None:
        assert n >= 2 and np.all(np.isfinite(shape.mean)) and np.all(np.isfinite(shape.basis))
        assert np.isfinite(shape.friction) and shape.friction >= 0


@EXAMPLES
@given(st.data(), st.integers(0, 4), st.integers(0, 4), st.integers(0, 5))
def test_shape_samples(data, n, count, history_length):
    dropped = data.draw(st.lists(st.integers(0, 8), max_size=6))
    msg = ShapeSamples(num_vertices=n, num_samples=count, samples=_floats(data, 2 * n * count),
                       history_length=history_length, dropped_segments=dropped)  # fmt: skip
    vertices = _convert(convert.samples_from_msg, msg)
    if vertices is not None:
        assert vertices.shape == (count, n, 2) and np.all(np.isfinite(vertices))
        assert all(0 <= i < history_length for i in dropped)


def _segments(data, plan_id=None):
    rows = data.draw(st.lists(st.tuples(SMALL, SMALL, SMALL, SMALL, st.integers(0, 255)),
                              max_size=5))  # fmt: skip
    ids = st.just(plan_id) if plan_id is not None else st.integers(0, 9)
    return [
        ContactSegment(start=Point(x=x0, y=y0), end=Point(x=x1, y=y1), status=s,
                       plan_id=data.draw(ids) if data.draw(st.booleans()) else plan_id or 0)
        for x0, y0, x1, y1, s in rows
    ]  # fmt: skip


@EXAMPLES
@given(st.data())
def test_contact_history(data):
    history = _convert(convert.history_from_segments, _segments(data))
    if history is not None:
        ends = np.concatenate([history.a, history.b])
        assert np.all(np.abs(ends) <= validate.MAX_COORDINATE_M)
        assert set(history.status.tolist()) <= {0, 1, 2, 3, 4}


@EXAMPLES
@given(st.data(), st.integers(0, 5), st.integers(1, 9))
def test_execution_report(data, outcome, plan_id):
    msg = ExecutionReport(plan_id=plan_id, outcome=outcome, segments=_segments(data, plan_id),
                          stop_point=Point(x=data.draw(SMALL), y=data.draw(SMALL)))  # fmt: skip
    report = _convert(convert.report_from_msg, msg)
    if report is not None:
        assert outcome in convert.OUTCOMES and np.all(np.isfinite(report.stop_point))
        assert all(s.plan_id == plan_id for s in msg.segments)


@EXAMPLES
@given(st.data(), st.integers(0, 3))
def test_docking_plan(data, decision):
    points = data.draw(st.lists(st.tuples(SMALL, SMALL), max_size=4))
    msg = DockingPlan(
        decision=decision, waypoints=[Point(x=x, y=y) for x, y in points],
        load_direction=Vector3(x=data.draw(SMALL), y=data.draw(SMALL)),
        contact_force_threshold=data.draw(SMALL), max_speed=data.draw(SMALL),
        docking_probability=data.draw(SMALL),
    )  # fmt: skip
    plan = _convert(convert.plan_from_msg, msg)
    if plan is not None and plan.dock:
        assert len(plan.waypoints) >= 2 and np.all(np.isfinite(plan.waypoints))
        assert abs(np.linalg.norm(plan.load) - 1.0) <= convert.UNIT_TOLERANCE
        assert plan.force_threshold > 0 and 0 < plan.max_speed < np.inf


def test_huge_plan_vectors_are_rejected_without_overflow_warnings():
    """Finite but huge load or waypoints: rejected, with no RuntimeWarning (hypothesis found
    overflow warnings in these property tests)."""
    base = dict(decision=DockingPlan.DOCK, contact_force_threshold=5.0, max_speed=0.1)
    line = [Point(x=0.0, y=0.0), Point(x=0.0, y=-0.1)]
    cases = [
        (DockingPlan(**base, waypoints=line, load_direction=Vector3(x=1e200, y=1e200)), "unit"),
        (
            DockingPlan(
                **base,
                waypoints=[Point(x=-1e308, y=0.0), Point(x=1e308, y=0.0)],
                load_direction=Vector3(x=1.0, y=0.0),
            ),
            "waypoints has a coordinate beyond 1e\\+06 m",
        ),
    ]
    for msg, message in cases:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            with pytest.raises(MessageError, match=message):
                convert.plan_from_msg(msg)


@EXAMPLES
@given(st.integers(0, 255), st.integers(0, 2**32 - 1), st.lists(
    st.tuples(SMALL, SMALL, SMALL, SMALL, st.integers(0, 255)), max_size=4))  # fmt: skip
def test_episode_status(state, episode, rows):
    cycles = [EpisodeCycle(docking_probability=p, inference_time=i, planning_time=t,
                           execution_time=e, outcome=o) for p, i, t, e, o in rows]  # fmt: skip
    msg = EpisodeStatus(state=state, episode=episode, cycles=cycles)
    parsed = _convert(convert.episode_status_from_msg, msg)
    assert (parsed is not None) == (state < len(convert.EPISODE_STATES))
    if parsed is not None:
        assert parsed == (convert.EPISODE_STATES[state], episode)
    records = _convert(convert.episode_cycles_from_msg, msg)
    if records is not None:
        assert len(records) == len(rows) and all(o in (*range(4), 254, 255) for *_, o in rows)
        assert np.all(np.isfinite([r["p_dock"] + r["inference_s"] for r in records]))


@EXAMPLES
@given(
    st.integers(0, 40), st.integers(0, 40), st.sampled_from(["16UC1", "32FC1", "rgb8", "", "8UC1"]),
    st.integers(0, 200), st.binary(max_size=3000), st.booleans(),
)  # fmt: skip
def test_depth_image(width, height, encoding, step, data, bigendian):
    msg = Image(width=width, height=height, encoding=encoding, step=step, data=data,
                is_bigendian=bigendian)  # fmt: skip
    depth = _convert(convert.depth_from_image, msg)
    if depth is not None:
        assert depth.shape == (height, width) and len(data) == step * height


@EXAMPLES
@given(st.lists(SMALL, min_size=9, max_size=9), st.integers(0, 50), st.integers(0, 50))
def test_camera_info(k, width, height):
    K = _convert(convert.intrinsics_from_camera_info, CameraInfo(k=k, width=width, height=height))
    if K is not None:
        assert width * height > 0 and np.all(np.isfinite(K)) and K[0, 0] > 0 and K[1, 1] > 0


@EXAMPLES
@given(st.integers(-(2**31), 2**31 - 1), st.integers(0, 2**32 - 1))
def test_stamp(sec, nanosec):
    now_ns = 1_800_000_000 * 10**9
    ok = _raises_not(validate.check_stamp, "x", Time(sec=sec, nanosec=nanosec), now_ns)
    lead = sec + nanosec * 1e-9 - now_ns * 1e-9
    assert ok == (sec >= 0 and nanosec < 10**9 and lead <= validate.MAX_STAMP_LEAD_S)


def _raises_not(fn, *args) -> bool:
    try:
        fn(*args)
    except MessageError:
        return False
    return True


def test_frame_check():
    msg = ShapeSamples(header=Header(frame_id="dock_plane"))
    validate.check_frame("samples", msg, "dock_plane")
    msg.header.frame_id = "camera"
    assert not _raises_not(validate.check_frame, "samples", msg, "dock_plane")


def test_bounds_are_checked_on_the_length_fields_before_any_array_is_read():
    # A num_samples past the limit is refused from the field alone (samples is empty here).
    msg = ShapeSamples(num_vertices=3, num_samples=validate.MAX_SAMPLES + 1)
    assert not _raises_not(convert.samples_from_msg, msg)
    msg = Image(width=2**16, height=2**16, encoding="32FC1", step=2**18)
    assert not _raises_not(convert.depth_from_image, msg)


class _Logger:
    def __init__(self):
        self.lines = []

    def error(self, text):
        self.lines.append(text)


def test_drop_log_is_throttled_per_cause():
    clock = [0.0]
    logger = _Logger()
    log = MalformedLog(logger, period_s=10.0, clock=lambda: clock[0])
    for value in range(5):  # one cause: only the values differ
        log.drop("/plan", MessageError(f"load_direction must be a unit vector, got [{value} 1]"))
    log.drop("/plan", MessageError("unknown decision 9"))  # another cause
    log.drop("/wrench", MessageError("unknown decision 9"))  # another topic
    assert len(logger.lines) == 3 and log.dropped == {"/plan": 6, "/wrench": 1}
    clock[0] = 10.5
    log.drop("/plan", MessageError("load_direction must be a unit vector, got [7 1]"))
    assert len(logger.lines) == 4 and "4 more dropped for this cause" in logger.lines[-1]


def test_every_node_subscribes_through_the_guard():
    nodes = REPO_ROOT / "tactile_dock_ros" / "nodes"
    direct = [p.name for p in nodes.glob("*.py")
              if p.name != "common.py" and "create_subscription(" in p.read_text()]  # fmt: skip
    assert direct == []
    uses = sum(len(re.findall(r"\bsubscribe\(", p.read_text())) for p in nodes.glob("*_node.py"))
    assert uses >= 5


def _prior(n=50, m=6, seed=0):
    from tactile_dock_ros.core.shape import GaussianShape

    rng = np.random.default_rng(seed)
    return GaussianShape(rng.normal(size=2 * n), 0.01 * rng.normal(size=(2 * n, m)), False, 0.5)


def test_samples_drawn_from_the_prior_fit_it_others_are_refused():
    prior = _prior()
    rng = np.random.default_rng(1)
    drawn = prior.vertices(5.0 * rng.standard_normal((200, prior.n_basis)))  # far tails too
    validate.samples_fit_prior(drawn, prior.n_vertices, prior.mean, prior.basis)
    validate.samples_fit_prior(None, prior.n_vertices, prior.mean, prior.basis)  # empty set
    with pytest.raises(MessageError, match="samples have 3 vertices, the prior has 50"):
        validate.samples_fit_prior(drawn[:, :3], 3, prior.mean, prior.basis)
    with pytest.raises(MessageError, match="samples have 3 vertices"):
        validate.samples_fit_prior(None, 3, prior.mean, prior.basis)
    huge = prior.mean.reshape(1, -1, 2) * 1e150
    with pytest.raises(MessageError, match="from the prior mean, beyond 100 prior std"):
        validate.samples_fit_prior(huge, prior.n_vertices, prior.mean, prior.basis)
    moved = drawn.copy()
    std = np.linalg.norm(prior.basis, axis=1).reshape(-1, 2)
    moved[7, 4, 1] = prior.mean.reshape(-1, 2)[4, 1] + 101 * std[4, 1] + 2e-3
    with pytest.raises(MessageError, match="sample 7 coordinate 9 "):
        validate.samples_fit_prior(moved, prior.n_vertices, prior.mean, prior.basis)


def test_a_prior_without_spread_admits_its_mean_within_the_slack():
    prior = _prior(n=4, m=0)
    at_mean = prior.mean.reshape(1, 4, 2) + 0.5 * validate.SAMPLE_PRIOR_SLACK_M
    validate.samples_fit_prior(at_mean, 4, prior.mean, prior.basis)
    with pytest.raises(MessageError):
        validate.samples_fit_prior(at_mean + validate.SAMPLE_PRIOR_SLACK_M, 4, prior.mean,
                                   prior.basis)  # fmt: skip
