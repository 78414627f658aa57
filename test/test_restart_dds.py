"""Restart without loss, over DDS: kill -9 inference or planner mid-episode, start it again.

The five processes of the mock profile (tools.restart_faults, what ``ros2 launch`` starts); the
node dies while the executor runs the episode's second plan. The episode then goes on with the
whole contact history: the next plan is made on every segment reported so far, the pre-kill
history unchanged, under the same episode id, and inference samples warm from the posterior
its predecessor saved. Killing the planner also stops the arm within the
executor's producer_timeout (the running attempt ends ABORTED, "producer lost").
"""

import pytest

from tactile_dock_ros.tools import restart_faults

pytestmark = pytest.mark.dds


def _logs(tmp_path) -> str:
    return "\n".join(f"--- {p.name}\n{p.read_text()[-1500:]}" for p in tmp_path.glob("*/*.log"))


def _assert_resumed_with_the_whole_history(run: dict, tmp_path) -> None:
    assert run["same_episode"], _logs(tmp_path)
    assert run["history_kept"], run
    assert run["history_after"] == run["history_expected"] >= run["history_before"] > 0, run


def _run(node: str, tmp_path) -> dict:
    """``restart_faults.run`` on the first of three terrains whose episode reaches a second
    move (which one does depends on the episode's course, e.g. a give-up at cycle 2 when the
    non-compliant slide leaves no site inside the workspace box)."""
    for seed in (5, 6, 7):
        try:
            return restart_faults.run(node, tmp_path / f"seed_{seed}", seed)
        except restart_faults.EndedBeforeFault as err:
            ended = err
    raise ended


def test_a_killed_inference_node_restarts_with_the_full_history(tmp_path):
    run = _run("inference", tmp_path)
    _assert_resumed_with_the_whole_history(run, tmp_path)
    # The attempt that ended while inference was down is in too (the latched reports).
    assert run["history_expected"] > run["history_before"], run
    assert run["warm_start_restored"], _logs(tmp_path)  # the saved posterior, not a cold start


def test_a_killed_planner_stops_the_arm_and_resumes_the_episode(tmp_path):
    run = _run("planner", tmp_path)
    assert run["producer_lost"], run["stop_detail"]
    assert run["stopped"]  # zero commands from the stop to the restart
    # Stopped after producer_timeout without copies of the plan, plus a control tick and
    # scheduling on a loaded machine.
    assert restart_faults.PRODUCER_TIMEOUT_S <= run["stop_s"] + 0.5 < 5.0, run
    _assert_resumed_with_the_whole_history(run, tmp_path)
