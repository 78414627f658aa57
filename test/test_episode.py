"""The exploration cycle's state (core.episode.EpisodeState) and the planner settings
(PlannerConfig): appends stay consistent, bad input is refused with the field named."""

import dataclasses

import numpy as np
import pytest

from tactile_dock_ros.core.episode import EpisodeState, PlannerConfig
from tactile_dock_ros.core.history import History, Status
from tactile_dock_ros.core.sampling import Deferral


def _evidence(rows: int, x: float = 0.0) -> History:
    a = np.stack([np.full(rows, x), np.linspace(0.5, 0.3, rows)], axis=1)
    status = [Status.FREE] * (rows - 1) + [Status.SLIP_LEFT]
    return History(a, a + np.array([0.0, -0.05]), status)


def test_a_new_state_knows_nothing():
    state = EpisodeState()
    assert len(state.history) == 0 and state.move_ids.shape == (0,)
    assert state.dropped.shape == (0,) and state.targets.shape == (0, 2)
    assert state.tool is None and state.warm_start is None


def test_record_appends_each_plans_evidence_with_its_id():
    state = EpisodeState(tool=[0.0, 0.4]).record(_evidence(2), 1).record(_evidence(3, 0.1), 3)
    assert len(state.history) == 5 and state.move_ids.tolist() == [1, 1, 3, 3, 3]
    np.testing.assert_array_equal(state.history.a[2:], _evidence(3, 0.1).a)
    np.testing.assert_array_equal(state.tool, [0.0, 0.4])  # the rest is kept
    assert len(state.record(History(), 4).history) == 5  # a plan that felt nothing


@pytest.mark.parametrize("plan_id", [0, -1, 3, 2, 2.5])
def test_record_refuses_a_plan_id_out_of_order(plan_id):
    state = EpisodeState().record(_evidence(1), 3)
    with pytest.raises(ValueError, match="plan id"):
        state.record(_evidence(1), plan_id)


def test_changes_return_a_new_state_and_leave_the_old_one_alone():
    state = EpisodeState()
    later = state.record(_evidence(2), 1).aim([0.1, 0.2]).move([0.0, 0.3])
    assert len(state.history) == 0 and len(state.targets) == 0 and state.tool is None
    assert later.targets.tolist() == [[0.1, 0.2]] and later.tool.tolist() == [0.0, 0.3]
    with pytest.raises(dataclasses.FrozenInstanceError):
        later.tool = None
    with pytest.raises(ValueError, match="read-only"):
        later.move_ids[0] = 5


def test_the_arrays_are_copies_of_the_callers():
    tool, z = np.array([0.0, 0.3]), np.ones((4, 2))
    state = EpisodeState(tool=tool, warm_start=z)
    tool[0], z[0, 0] = 9.0, 9.0
    assert state.tool[0] == 0.0 and state.warm_start[0, 0] == 1.0
    assert tool.flags.writeable and z.flags.writeable


def test_sampled_sets_the_warm_start_and_the_dropped_rows():
    state = EpisodeState().record(_evidence(3), 1).sampled(np.ones((5, 2)), [2])
    assert state.warm_start.shape == (5, 2) and state.dropped.tolist() == [2]
    assert state.record(_evidence(1), 2).dropped.tolist() == [2]  # still row 2 of the longer
    assert state.sampled(np.zeros((0, 2))).warm_start is None  # no rows: sample cold
    assert state.sampled().dropped.tolist() == []


def test_deferred_rows_are_kept_with_the_state_and_ignored_with_the_dropped_ones():
    deferral = Deferral([0, 2], [1, 3], np.ones((4, 2)))
    state = EpisodeState().record(_evidence(3), 1).sampled(np.ones((5, 2)), [1], deferral)
    assert state.deferred.tolist() == [0, 2] and state.ignored.tolist() == [0, 1, 2]
    later = state.record(_evidence(1), 2)  # the rows still index the older ones
    assert later.deferral is deferral and later.ignored.tolist() == [0, 1, 2]
    assert later.with_history(_evidence(1), [3]).deferred.tolist() == []
    assert state.sampled().deferred.tolist() == [] and EpisodeState().ignored.tolist() == []
    with pytest.raises(ValueError, match="deferred rows"):
        EpisodeState(_evidence(2), deferral=Deferral([2], [1]))
    with pytest.raises(ValueError, match="effort"):
        Deferral([0, 1], [1])


def test_with_history_replaces_the_evidence_and_clears_the_dropped_rows():
    state = EpisodeState(tool=[0.0, 0.3]).record(_evidence(3), 1).sampled(dropped=[2])
    received = state.with_history(_evidence(1), [4])
    assert len(received.history) == 1 and received.move_ids.tolist() == [4]
    assert received.dropped.tolist() == [] and received.tool.tolist() == [0.0, 0.3]
    assert EpisodeState(_evidence(2)).move_ids.tolist() == [0, 0]  # unknown moves by default


@pytest.mark.parametrize(
    "fields, message",
    [
        (dict(history=_evidence(2), move_ids=[1]), "move_ids has 1 entries for 2 rows"),
        (dict(history=_evidence(2), move_ids=[1, -1]), "move ids must be >= 0"),
        (dict(history=_evidence(2), dropped=[2]), "outside the 2-row history"),
        (dict(dropped=[-1]), "outside the 0-row history"),
        (dict(targets=[[0.0, np.nan]]), "targets must be finite"),
        (dict(targets=[0.0, 1.0, 2.0]), r"targets must have shape \(-1, 2\)"),
        (dict(tool=[0.0, np.inf]), "tool position must be finite"),
        (dict(tool=[0.0, 0.1, 0.2]), r"tool position must have shape \(2,\)"),
        (dict(warm_start=[[np.nan]]), "warm start must be finite"),
    ],
)
def test_a_bad_state_is_refused(fields, message):
    with pytest.raises(ValueError, match=message):
        EpisodeState(**fields)


def test_planner_config_normalizes_the_load():
    config = PlannerConfig(load=np.array([0.0, -2.0]))
    assert config.load == (0.0, -1.0)
    assert dataclasses.replace(config, objective="greedy").load == (0.0, -1.0)
    assert config == PlannerConfig()  # comparable: the load is a tuple


@pytest.mark.parametrize(
    "fields, message",
    [
        (dict(load=(0.0, 0.0)), "load must be a finite nonzero 2-vector"),
        (dict(load=(np.nan, -1.0)), "load must be a finite nonzero 2-vector"),
        (dict(load=(0.0, -1.0, 0.0)), "load must be a finite nonzero 2-vector"),
        (dict(contact_resolution=0.0), "contact_resolution must be > 0 metres"),
        (dict(contact_resolution=np.inf), "contact_resolution must be > 0 metres"),
        (dict(give_up_threshold=1.0), r"give_up_threshold must be in \[0, 1\)"),
        (dict(give_up_threshold=-0.1), r"give_up_threshold must be in \[0, 1\)"),
        (dict(give_up_threshold=np.nan), r"give_up_threshold must be in \[0, 1\)"),
        (dict(objective="nonsense"), "unknown objective 'nonsense'"),
        (dict(compliant="yes"), "compliant must be a bool"),
        (dict(max_path_attempts=0), "max_path_attempts must be >= 1"),
        (dict(max_path_attempts=2.5), "max_path_attempts must be >= 1"),
        (dict(max_path_attempts=True), "max_path_attempts must be >= 1"),
    ],
)
def test_a_bad_planner_setting_is_refused(fields, message):
    with pytest.raises(ValueError, match=message):
        PlannerConfig(**fields)
