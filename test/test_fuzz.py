"""Fuzzing every subscription of every node, reduced: the bench runs 1000 / topic.

In-process, every malformed message reaches a guarded callback and is dropped, nothing escapes,
inference's history is untouched and the executor takes no plan while no episode runs. Over
DDS, with the five nodes as processes: no node dies or prints a traceback, the seeded contact
history is exactly extended by a valid probe report afterwards, a normal episode still docks,
and the malformed input is logged throttled (far fewer lines than drops).
"""

import pytest

from tactile_dock_ros.nodes.common import MALFORMED_LOG_PERIOD_S
from tactile_dock_ros.tools import fuzz

IN_PROCESS_MESSAGES, DDS_MESSAGES = 40, 100


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    return fuzz.in_process(IN_PROCESS_MESSAGES, 0, tmp_path_factory.mktemp("params"))


def _topics(in_process):
    return {
        (node, topic): row
        for node, rows in in_process.items()
        for topic, row in rows.items()
        if isinstance(row, dict)
    }


def test_every_malformed_message_is_dropped_by_every_subscriber(in_process):
    topics = _topics(in_process)
    assert {node for node, _ in topics} == {
        "perception", "inference", "planner", "executor", "mock_hardware",
    }  # fmt: skip
    for key, row in topics.items():
        assert row["exceptions"] == {}, (key, row)
        accepted = {k: v for k, v in row.items() if k.startswith("accepted malformed")}
        assert accepted == {}, (key, accepted)
        assert row["malformed"] > 0 and row["dropped"] >= row["malformed"], (key, row)


def test_stale_ids_leave_the_history_and_the_arm_alone(in_process):
    # Duplicated / out-of-order plan and episode ids, reports of other episodes: well formed,
    # ignored by design (inference), and no plan is taken while the planner's episode is IDLE
    # (dropped, or refused with an ABORTED report: counted alike).
    assert in_process["inference"]["history_unchanged"]
    plans = in_process["executor"]["/plan"]
    assert plans["well_formed"] > 0 and plans["dropped"] == IN_PROCESS_MESSAGES


@pytest.mark.slow  # every subscription's guard is fuzzed in-process by default
@pytest.mark.dds
def test_fuzz_over_dds_kills_nothing_and_the_suite_still_docks(tmp_path, in_process):
    expected = set(_topics(in_process))
    result = fuzz.over_dds(DDS_MESSAGES, 0, tmp_path, 180.0, expected, progress=print)
    logs = "\n".join(p.read_text()[-2000:] for p in tmp_path.glob("*.log"))
    # Every subscription of every node (read from the ROS graph) was fuzzed, the same ones the
    # node objects hold in-process.
    graph = {(n, t) for t, row in result["topics"].items() for n in row["subscribers"]}
    assert graph == expected
    assert all(row["sent"] == DDS_MESSAGES for row in result["topics"].values())
    assert result["deaths"] == 0 and result["tracebacks"] == 0, logs
    assert result["history_seeded"]
    assert result["history"]["probe_answered"] and not result["history"]["corrupted"], logs
    assert result["episode"]["state"] == "DOCKED", logs
    # Logged once per cause and topic per period: at most (kinds sent) x (periods) lines per
    # node, and fewer lines than drops overall.
    periods = 1 + result["fuzz_seconds"] / MALFORMED_LOG_PERIOD_S
    for name, node in result["nodes"].items():
        kinds = sum(len(row["kinds"]) for row in result["topics"].values()
                    if name in row["subscribers"])  # fmt: skip
        assert sum(node["dropped"].values()) > 0, name
        assert node["drop_log_lines"] <= kinds * periods, (name, node)
    lines = sum(node["drop_log_lines"] for node in result["nodes"].values())
    assert lines < sum(sum(node["dropped"].values()) for node in result["nodes"].values())
