"""bench episode's bookkeeping: how an episode ended, per-problem counts, bad arguments."""

import argparse

import pytest
from std_msgs.msg import Header

from tactile_dock_ros.nodes import convert
from tactile_dock_ros.tools import bench
from tactile_dock_ros.tools.bench import episode as bench_episode
from tactile_dock_ros.tools.episode import EpisodeRecord


@pytest.mark.parametrize(
    ("state", "detail", "expected"),
    [
        ("DOCKED", "docked", "docked"),
        ("GAVE_UP", "best docking probability 2.00e-04 < threshold 0.001", "planner"),
        (
            "GAVE_UP",
            "best docking probability of a whole path 3.10e-04 < threshold 0.001 (4 sites' paths)",
            "planner",
        ),
        ("GAVE_UP", "the tool is inside the likely-obstacle region with no way out", "no_path"),
        ("GAVE_UP", "no collision-free prefix to any promising docking site", "no_path"),
        ("GAVE_UP", "no edge of the shape faces the load direction", "planner"),
        ("GAVE_UP", "cycle budget of 8 spent", "budget"),
        ("GAVE_UP", "inference found no shape consistent with the contact history", "no_shape"),
        ("ABORTED", "sensor timeout", "aborted"),
    ],
)
def test_ended_by(state, detail, expected):
    status = convert.episode_status_to_msg(Header(), state, 7, detail, 12, [])
    assert bench_episode.ended_by(EpisodeRecord(status=status)) == expected
    assert bench_episode.ended_by(EpisodeRecord()) == "none"


def _episode(feasible, ended_by, cycles):
    state = {"docked": "DOCKED", "aborted": "ABORTED"}.get(ended_by, "GAVE_UP")
    stages = {k: [1.0] for k in ("inference_s", "planning_s", "execution_s")}
    return {"feasible": feasible, "ended_by": ended_by, "state": state, "cycles": cycles,
            "wall_s": 10.0, "perception_s": 0.01, **stages}  # fmt: skip


def test_summary_separates_planner_give_ups_from_the_budget_and_stuck_planners():
    episodes = [
        _episode(True, "docked", 1),
        _episode(True, "aborted", 1),
        _episode(False, "planner", 3),
        _episode(False, "planner", 5),
        _episode(False, "budget", 8),
        _episode(False, "no_path", 2),
    ]
    s = bench_episode.summary(episodes)
    assert (s["episodes"], s["feasible"], s["docked_on_feasible"]) == (6, 2, 1)
    assert s["infeasible_planner_give_up"] == 2 and s["infeasible_budget"] == 1
    assert s["infeasible_planner_give_up_cycles_median"] == 4.0
    assert s["other"] == 2 and s["cycles_median"] == 2.5


@pytest.mark.parametrize(
    "bad", [["--seeds", "0"], ["--problems", "boulder"], ["--prior-source", "moon"]]
)
def test_bad_arguments_are_rejected(bad):
    with pytest.raises(SystemExit) as exit_info:
        bench.main(["episode", *bad])
    assert exit_info.value.code == 2


@pytest.mark.parametrize("source", ["depth", "generic", "problem", "learned"])
def test_each_prior_source_of_the_launch_file_is_offered(source):
    """Every prior_source perception takes (``launch/tactile_dock.launch.xml``) can be asked."""
    parser = argparse.ArgumentParser()
    bench_episode.add_arguments(parser)
    assert parser.parse_args(["--prior-source", source]).prior_source == source
