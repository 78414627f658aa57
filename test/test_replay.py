"""Bags and offline replay: tools.bag round-trips messages; tools.replay rebuilds each recorded
cycle's planner inputs and reproduces the recorded plans, or shows what a changed parameter
would have done. The recorded episode here is built without DDS from the same core calls the
nodes make; test_system.py replays a bag recorded from the real node processes.
"""

import argparse
import contextlib
import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from message_samples import build as sample_messages
from std_msgs.msg import Header
from tactile_dock_ros.msg import ExecutionReport

from tactile_dock_ros.core import planner, problems, simulate
from tactile_dock_ros.core.episode import EpisodeState
from tactile_dock_ros.core.sampling import sample_posterior
from tactile_dock_ros.execution.types import PlanCommand, Report
from tactile_dock_ros.nodes import convert
from tactile_dock_ros.tools import bag, package_files, replay


def _settings(**given):
    names = ("config", "give_up_threshold", "contact_resolution", "compliant")
    return replay.settings_from(argparse.Namespace(**{n: given.get(n) for n in names}))


DEFAULTS = _settings()  # the planner node's defaults
CYCLES, RESENDS = 3, 2


def _header(ns: int) -> Header:
    header = Header(frame_id="dock_plane")
    header.stamp.sec, header.stamp.nanosec = divmod(ns, 10**9)
    return header


def _record_episode(rng, messages: list, t0: int, episode: int) -> None:
    """CYCLES plans on a sloper truth, as the nodes publish them (every plan resent)."""
    problem = problems.get("sloper")
    truth = problem.sample_ground_truth(np.random.default_rng(5))
    clock = iter(range(t0, t0 + 10**9, 1000))

    def put(topic, to_msg, value, *rest):  # every convert.*_to_msg takes the header second
        t = next(clock)
        messages.append((topic, t, to_msg(value, _header(t), *rest)))

    state = EpisodeState(tool=problem.start)
    config = dataclasses.replace(DEFAULTS.config, load=problem.load, compliant=False)
    put("/terrain_prior", convert.shape_to_msg, problem.prior)
    for plan_id in range(1, CYCLES + 1):
        history = state.history
        put("/contact_history", convert.history_to_msg, state)
        samples = sample_posterior(problem.prior, history, 40, rng).vertices
        put("/shape_samples", convert.samples_to_msg, samples, "hmc", 1.0, len(history))
        result = planner.plan(samples, problem.prior, state, config)
        dock = result.decision == "dock"
        command = PlanCommand(
            plan_id,
            dock,
            result.path if dock else state.tool[None],
            problem.load,
            3.0,
            0.1,
            False,
            result.p_dock,
            result.objective,
            result.target_edge,
            result.reason,
            result.target_point,
            episode,
            len(history),
        )
        plan_msg = convert.plan_to_msg(command, _header(next(clock)))
        for _ in range(RESENDS):
            messages.append(("/plan", next(clock), plan_msg))
        if not dock:
            continue
        run = simulate.guarded_path(
            truth,
            problem.prior.closed,
            result.path,
            problem.prior.friction,
            problem.load,
            compliant=False,
            contact_resolution=config.contact_resolution,
        )
        outcome = (
            ExecutionReport.DOCKED
            if run.docked
            else ExecutionReport.CONTACT_FAILED
            if run.contact
            else ExecutionReport.NO_CONTACT
        )
        report = Report(plan_id, outcome, run.observations, run.stop_point, "", episode)
        put("/execution_report", convert.report_to_msg, report)
        state = state.record(run.observations, plan_id).aim(result.target_point)
        state = state.move(run.stop_point)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A bag with two episodes of CYCLES recorded plans each."""
    messages, rng = [], np.random.default_rng(0)
    _record_episode(rng, messages, 0, 1795315710)
    _record_episode(rng, messages, 10**9, 1795316710)
    path = tmp_path_factory.mktemp("bags") / "episode"
    assert bag.write(path, messages) == len(messages)
    return path


@pytest.mark.parametrize("storage", bag.STORAGES)
def test_every_episode_message_survives_a_bag_round_trip(tmp_path, storage):
    samples = sample_messages()
    topics = {t.rsplit("/", 1)[-1]: t for t in bag.EPISODE_TOPICS.values()}
    written = [
        (topic, 1000 + i, samples[kind.rsplit("/", 1)[-1]])
        for i, (topic, kind) in enumerate(bag.EPISODE_TOPICS.items())
        if kind.rsplit("/", 1)[-1] in samples
    ]
    assert len(written) == len(topics)
    bag.write(tmp_path / "b", written, storage=storage)
    assert list(bag.read(tmp_path / "b")) == written
    files = [p.suffix for p in (tmp_path / "b").iterdir() if p.name != "metadata.yaml"]
    assert files == [{"mcap": ".mcap", "sqlite3": ".db3"}[storage]]


def _announced_type_hashes() -> dict:
    """Topic -> the RIHS01 hash rclpy's publisher of its type announces on the graph."""
    from ros_helpers import ros_node

    with ros_node("type_hashes") as (node, _):
        for topic, msgtype in bag.EPISODE_TOPICS.items():
            node.create_publisher(bag.message_class(msgtype), topic, 1)
        return {
            topic: str(node.get_publishers_info_by_topic(topic)[0].topic_type_hash)
            for topic in bag.EPISODE_TOPICS
        }


@pytest.mark.parametrize("storage", bag.STORAGES)
def test_a_bag_names_the_ros_distro_and_type_hashes_as_rosbag2_writes_them(
    tmp_path, storage, monkeypatch
):
    """rosbag2 stores $ROS_DISTRO and each topic's RIHS01 hash (metadata.yaml, the bag's own
    metadata copy; MCAP channels: ``topic_type_hash``). Without ROS_DISTRO (the PyPI wheels)
    the installed rclpy's distro; the hashes are those rclpy announces."""
    from importlib.metadata import version

    monkeypatch.delenv("ROS_DISTRO", raising=False)
    distro = {"7": "jazzy", "9": "kilted"}[version("ros-rclpy").split(".")[0]]
    announced = _announced_type_hashes()
    assert all(h.startswith("RIHS01_") for h in announced.values())
    samples = sample_messages()
    written = [(t, 1000, samples[k.rsplit("/", 1)[-1]]) for t, k in bag.EPISODE_TOPICS.items()]
    bag.write(tmp_path / "b", written, storage=storage)
    info = yaml.safe_load((tmp_path / "b" / "metadata.yaml").read_text())
    info = info["rosbag2_bagfile_information"]
    assert info["ros_distro"] == distro
    in_metadata = {
        t["topic_metadata"]["name"]: t["topic_metadata"]["type_description_hash"]
        for t in info["topics_with_message_count"]
    }
    assert in_metadata == announced
    if storage == "mcap":
        from mcap.reader import make_reader

        (file,) = (tmp_path / "b").glob("*.mcap")
        with open(file, "rb") as f:
            reader = make_reader(f)
            channels = reader.get_summary().channels.values()
            in_channels = {c.topic: c.metadata.get("topic_type_hash") for c in channels}
            (record,) = [m for m in reader.iter_metadata() if m.name == "rosbag2"]
        stored = yaml.safe_load(record.metadata["serialized_metadata"])
    else:
        import sqlite3

        (file,) = (tmp_path / "b").glob("*.db3")
        with contextlib.closing(sqlite3.connect(file)) as db:
            in_channels = dict(db.execute("SELECT name, type_description_hash FROM topics"))
            assert db.execute("SELECT ros_distro FROM schema").fetchall() == [(distro,)]
            (text,) = db.execute("SELECT metadata FROM metadata").fetchone()
        stored = yaml.safe_load(text)
    assert in_channels == announced
    assert stored["ros_distro"] == distro
    assert list(bag.read(tmp_path / "b")) == written  # still a bag rosbags reads
    monkeypatch.setenv("ROS_DISTRO", "rolling")  # set (a sourced ROS 2): as rosbag2, that one
    bag.write(tmp_path / "c", written, storage=storage)
    info = yaml.safe_load((tmp_path / "c" / "metadata.yaml").read_text())
    assert info["rosbag2_bagfile_information"]["ros_distro"] == "rolling"


def _offered(qos_yaml) -> dict:
    """Durability, reliability and depth of the one profile in offered_qos_profiles."""
    (profile,) = yaml.safe_load(qos_yaml) if isinstance(qos_yaml, str) else qos_yaml
    return {k: profile[k] for k in ("durability", "reliability", "depth")}


EXPECTED_QOS = {  # what the nodes publish with (nodes.qos); latched topics replay latched
    "/terrain_prior": {"durability": "transient_local", "reliability": "reliable", "depth": 8},
    "/contact_history": {"durability": "transient_local", "reliability": "reliable", "depth": 1},
    "/shape_samples": {"durability": "transient_local", "reliability": "reliable", "depth": 1},
    "/plan": {"durability": "volatile", "reliability": "reliable", "depth": 100},
    "/execution_report": {"durability": "transient_local", "reliability": "reliable", "depth": 32},
}


def test_a_bag_stores_each_topics_qos_and_reads_with_the_mcap_packages(recorded):
    """Read by others' code (``mcap`` + ``mcap-ros2-support``): rosbag2's profile, each
    channel's offered QoS as rosbag2 stores it (also in metadata.yaml), decodable messages."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    info = yaml.safe_load((recorded / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["storage_identifier"] == "mcap" and info["version"] == bag.BAG_VERSION
    in_metadata = {
        t["topic_metadata"]["name"]: _offered(t["topic_metadata"]["offered_qos_profiles"])
        for t in info["topics_with_message_count"]
    }
    assert in_metadata == EXPECTED_QOS
    (file,) = recorded.glob("*.mcap")
    with open(file, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        channels = reader.get_summary().channels.values()
        in_channels = {c.topic: _offered(c.metadata["offered_qos_profiles"]) for c in channels}
        assert in_channels == EXPECTED_QOS
        decoded = [(c.topic, m.log_time, d) for _, c, m, d in reader.iter_decoded_messages()]
    ours = list(bag.read(recorded))
    assert [(t, ns) for t, ns, _ in decoded] == [(t, ns) for t, ns, _ in ours]
    plans = [(d.plan_id, d.episode) for t, _, d in decoded if t == "/plan"]
    assert plans == [(m.plan_id, m.episode) for t, _, m in ours if t == "/plan"]


def test_the_replay_reads_an_sqlite3_bag_as_the_mcap_one(recorded, tmp_path):
    bag.write(tmp_path / "db3", bag.read(recorded), storage="sqlite3")

    def fields(path) -> list:  # repr: a GIVE_UP plan's NaN target is not == itself
        return [(topic, t, repr(msg)) for topic, t, msg in bag.read(path)]

    assert fields(tmp_path / "db3") == fields(recorded)
    cycles = replay.load_cycles(tmp_path / "db3")
    assert [c.recorded.plan_id for c in cycles] == [1, 2, 3] * 2
    assert all(replay.compare(c, replay.replan(c, DEFAULTS))["same"] for c in cycles)
    with pytest.raises(bag.BagError, match="storage"):
        bag.write(tmp_path / "other", [], storage="rosbag1")


def test_replay_reproduces_every_recorded_plan(recorded, tmp_path, capsys):
    cycles = replay.load_cycles(recorded)
    assert len(cycles) == 2 * CYCLES  # resent copies are one plan; two episodes
    assert [c.episode for c in cycles] == [1795315710] * CYCLES + [1795316710] * CYCLES
    first, second = cycles[0], cycles[1]
    assert len(first.state.targets) == 0 and len(cycles[CYCLES].state.targets) == 0
    if first.recorded.dock:  # eq. (24) novelty: the next cycle knows the earlier aim point
        assert first.outcome in ("DOCKED", "CONTACT_FAILED", "NO_CONTACT")  # its report
        np.testing.assert_array_equal(second.state.targets[0], first.recorded.target_point)
        assert second.state.move_ids.tolist() == [1] * len(second.state.history)  # plan 1's rows
    np.testing.assert_array_equal(first.state.tool, first.recorded.waypoints[0])
    rows = [replay.compare(c, replay.replan(c, DEFAULTS)) for c in cycles]
    assert all(r["same"] for r in rows), rows
    out = tmp_path / "replay.json"
    png = tmp_path / "replay.png"
    assert replay.main([str(recorded), "--json", str(out), "--png", str(png)]) == 0
    assert json.loads(out.read_text()) == rows
    assert png.stat().st_size > 10_000
    assert f"{2 * CYCLES}/{2 * CYCLES} cycles replayed to the same plan" in capsys.readouterr().out


def test_inputs_that_arrive_after_their_plan_still_match_it(recorded, tmp_path):
    # DDS orders one topic's messages, not different topics': put every history and samples
    # message after the plan that follows it, as a recorder may receive them
    messages = list(bag.read(recorded))
    late = {"/contact_history", "/shape_samples"}
    for i in range(len(messages) - 1):
        if messages[i][0] in late and messages[i + 1][0] == "/plan":
            messages[i], messages[i + 1] = messages[i + 1], messages[i]
    assert [m[0] for m in messages] != [m[0] for m in bag.read(recorded)]
    bag.write(tmp_path / "late", messages)
    cycles = replay.load_cycles(tmp_path / "late", log=print)
    assert len(cycles) == 2 * CYCLES
    assert all(replay.compare(c, replay.replan(c, DEFAULTS))["same"] for c in cycles)


def test_a_clock_offset_never_picks_another_episodes_inputs(recorded, tmp_path, capsys):
    # inference's clock 2 ms ahead of the planner's in the second episode: its samples are
    # stamped after the plans made from them, while the first episode has samples of the same
    # history lengths stamped before
    messages = []
    for topic, t, msg in bag.read(recorded):
        if topic == "/shape_samples" and t >= 10**9:
            stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec + 2_000_000
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp, 10**9)
        messages.append((topic, t, msg))
    bag.write(tmp_path / "skew", messages)
    cycles = replay.load_cycles(tmp_path / "skew")
    assert len(cycles) == 2 * CYCLES
    assert all(replay.compare(c, replay.replan(c, DEFAULTS))["same"] for c in cycles)
    assert "stamped after the plan" in capsys.readouterr().out


def test_a_bag_of_another_message_version_is_a_clear_error(recorded, monkeypatch):
    import rclpy.serialization

    def mismatch(raw, cls):
        raise RuntimeError("failed to deserialize ROS message")

    monkeypatch.setattr(rclpy.serialization, "deserialize_message", mismatch)
    with pytest.raises(bag.BagError, match="another version of the message"):
        list(bag.read(recorded))


def test_a_changed_parameter_shows_in_the_replay(recorded, tmp_path):
    out = tmp_path / "r.json"
    replay.main([str(recorded), "--give-up-threshold", "0.999", "--json", str(out)])
    rows = json.loads(out.read_text())
    assert all(r["replayed"]["decision"] == "give_up" for r in rows)
    docked = [r for r in rows if r["recorded"]["decision"] == "dock"]
    assert docked and not any(r["same"] for r in docked)


def test_resampling_plans_with_fresh_samples(recorded, tmp_path):
    out = tmp_path / "r.json"
    assert replay.main([str(recorded), "--resample", "30", "--seed", "3", "--json", str(out)]) == 0
    rows = json.loads(out.read_text())
    assert len(rows) == 2 * CYCLES
    assert any(r["recorded"]["p_dock"] != r["replayed"]["p_dock"] for r in rows)


def test_config_file_sets_the_planner_parameters(recorded, tmp_path):
    config = tmp_path / "planner.yaml"
    config.write_text("planner:\n  ros__parameters:\n    give_up_threshold: 0.5\n")
    settings = _settings(config=config, contact_resolution=0.02, compliant=True)
    assert (settings.config.give_up_threshold, settings.config.contact_resolution) == (0.5, 0.02)
    assert settings.compliant


def test_a_relative_config_missing_here_comes_from_the_installed_share(
    recorded, tmp_path, monkeypatch, capsys
):
    """From a colcon workspace the docs' ``--config config/...`` is not under the working
    directory: the installed share's file is used and named; neither: both places named."""
    from ament_index_python.packages import get_package_share_directory

    share = Path(get_package_share_directory("tactile_dock_ros"))
    monkeypatch.chdir(tmp_path)  # no config/ here
    assert replay.main([str(recorded), "--config", "config/robot.yaml"]) == 0
    assert f"using {share / 'config' / 'robot.yaml'}" in capsys.readouterr().err
    assert replay.main([str(recorded), "--config", "config/absent.yaml"]) == 2
    err = capsys.readouterr().err
    assert str(tmp_path / "config" / "absent.yaml") in err
    assert str(share / "config" / "absent.yaml") in err
    # the bench tools' inputs resolve through the same helper
    assert package_files.resolve("config/perception_mock.yaml", log=None) == (
        share / "config" / "perception_mock.yaml"
    )


def test_bad_input_is_a_clear_error(recorded, tmp_path, capsys):
    assert replay.main([str(tmp_path / "missing")]) == 2
    assert "not a rosbag2 bag directory" in capsys.readouterr().err
    assert replay.main([str(recorded), "--give-up-threshold", "1.5"]) == 2
    assert "give_up_threshold" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        replay.main([str(recorded), "--resample", "1"])
    plans_only = [m for m in bag.read(recorded) if m[0] == "/plan"]
    bag.write(tmp_path / "plans_only", plans_only)
    with pytest.raises(bag.BagError, match="no plan with its inputs"):
        replay.load_cycles(tmp_path / "plans_only", log=lambda _: None)
    with pytest.raises(bag.BagError, match="not one of"):
        bag.write(tmp_path / "other", [("/chatter", 0, plans_only[0][2])])
    with pytest.raises(bag.BagError, match="cannot write"):
        bag.write(recorded, plans_only)  # never overwrites
