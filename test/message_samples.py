"""One instance of every custom message with non-default values in every field."""

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Vector3
from std_msgs.msg import Header
from tactile_dock_ros.msg import (
    ContactHistory,
    ContactSegment,
    DockingPlan,
    EpisodeCycle,
    EpisodeStatus,
    ExecutionReport,
    SampleRequest,
    ShapeDistribution,
    ShapeSamples,
)


def _header(sec: int) -> Header:
    return Header(stamp=Time(sec=sec, nanosec=123_456_789), frame_id="dock_plane")


def _segment(i: int, status: int) -> ContactSegment:
    return ContactSegment(
        header=_header(10 + i),
        start=Point(x=0.1 * i, y=-0.25, z=0.0),
        end=Point(x=0.1 * i + 0.05, y=-0.5, z=0.0),
        status=status,
        plan_id=7 + i,
    )


def build() -> dict:
    """Message type name -> instance."""
    statuses = [
        ContactSegment.FREE,
        ContactSegment.COLLIDE,
        ContactSegment.STICK,
        ContactSegment.SLIP_LEFT,
        ContactSegment.SLIP_RIGHT,
    ]
    segments = [_segment(i, s) for i, s in enumerate(statuses)]
    cycles = [
        EpisodeCycle(docking_probability=0.5, inference_time=1.25, planning_time=0.5,
                     execution_time=3.5, outcome=EpisodeCycle.INTERRUPTED),
        EpisodeCycle(docking_probability=0.25, inference_time=0.75, planning_time=0.25,
                     execution_time=2.5, outcome=ExecutionReport.NO_CONTACT),
    ]  # fmt: skip
    return {
        "ShapeDistribution": ShapeDistribution(
            header=_header(1),
            hold_id=5,
            num_vertices=3,
            mean=[0.0, 0.0, 0.5, 0.1, 1.0, -0.2],
            num_basis=2,
            basis=[0.01 * k - 0.05 for k in range(12)],
            closed=True,
            friction=0.6,
            closure_edges=[2],
        ),
        "ContactSegment": segments[3],
        "ContactHistory": ContactHistory(header=_header(2), segments=segments),
        "ShapeSamples": ShapeSamples(
            header=_header(3),
            hold_id=5,
            num_vertices=2,
            num_samples=3,
            samples=[0.5 * k for k in range(12)],
            method="hmc",
            effective_sample_size=2.5,
            history_length=4,
            dropped_segments=[1, 3],
            compute_time=0.125,
        ),
        "SampleRequest": SampleRequest(
            header=_header(7),
            episode=1795315710,
            nonce=0x1234_5678_9ABC_DEF0,
            hold_id=5,
            history_length=4,
            num_samples=400,
        ),
        "DockingPlan": DockingPlan(
            header=_header(4),
            episode=1795315710,
            plan_id=42,
            nonce=0x1234_5678_9ABC_DEF0,
            history_length=17,
            decision=DockingPlan.GIVE_UP,
            waypoints=[Point(x=1.0, y=2.0, z=0.0), Point(x=1.5, y=1.0, z=0.0)],
            load_direction=Vector3(x=0.6, y=-0.8, z=0.0),
            contact_force_threshold=5.5,
            max_speed=0.05,
            compliant=True,
            docking_probability=0.75,
            objective=0.5,
            target_edge=17,
            target_point=Point(x=1.25, y=1.5, z=0.0),
            reason="best docking probability 0.0004 < threshold 0.001",
        ),
        "ExecutionReport": ExecutionReport(
            header=_header(5),
            episode=1795315710,
            plan_id=42,
            nonce=0x1234_5678_9ABC_DEF0,
            outcome=ExecutionReport.CONTACT_FAILED,
            segments=segments[:2],
            stop_point=Point(x=0.3, y=-0.4, z=0.0),
            detail="slipped right under the load",
        ),
        "EpisodeCycle": cycles[1],
        "EpisodeStatus": EpisodeStatus(
            header=_header(6),
            episode=1795315710,
            nonce=0x1234_5678_9ABC_DEF0,
            state=EpisodeStatus.GAVE_UP,
            hold_id=5,
            detail="cycle budget of 2 spent",
            prior_vertices=12,
            cycles=cycles,
        ),
    }
