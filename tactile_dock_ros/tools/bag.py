"""ROS 2 bags (rosbag2, MCAP or sqlite3 storage) of an episode's topics, without rosbag2.

On the robot, record what ``tools.replay`` needs with::

    ros2 bag record /terrain_prior /contact_history /shape_samples /plan /execution_report \\
        /episode_status

PyPI has no rosbag2, so here the pure-Python ``rosbags`` library reads and writes the same
format, and rclpy (de)serializes the messages (CDR): a bag written here plays with ``ros2 bag
play``, and a bag recorded on a robot reads here. Message definitions for the bag's metadata
come from this package's installed ``share/tactile_dock_ros/msg`` (the source tree's ``msg/``
when the package is not installed).

Storage: MCAP by default (rosbag2's default since Iron), sqlite3 on request; metadata version 9
(Jazzy's; later rosbag2 reads it). Each topic's ``offered_qos_profiles`` are stored (in
``metadata.yaml`` and, for MCAP, in the channel's metadata, as rosbag2 does): ``ros2 bag play``
offers what was recorded, so the latched topics replay TRANSIENT_LOCAL and reach the nodes'
TRANSIENT_LOCAL subscribers (a bag without profiles plays VOLATILE, which they never match).
The profiles are those the publishers offered when the caller observed them on the graph, else
the nodes' own (``QOS``).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path

from tactile_dock_ros.nodes import qos

# Topics (absolute names, default remappings) and their types, as the nodes publish them.
EPISODE_TOPICS = {
    "/terrain_prior": "tactile_dock_ros/msg/ShapeDistribution",
    "/contact_history": "tactile_dock_ros/msg/ContactHistory",
    "/shape_samples": "tactile_dock_ros/msg/ShapeSamples",
    "/plan": "tactile_dock_ros/msg/DockingPlan",
    "/execution_report": "tactile_dock_ros/msg/ExecutionReport",
    "/episode_status": "tactile_dock_ros/msg/EpisodeStatus",
}
# The QoS each topic is published with (nodes.qos): what a bag offers when it is played.
QOS = {
    "/terrain_prior": qos.LATCHED,
    "/contact_history": qos.LATCHED,
    "/shape_samples": qos.LATCHED,
    "/plan": qos.EVENTS,
    "/execution_report": qos.REPORTS,
    "/episode_status": qos.LATCHED,
}
BAG_VERSION = 9  # rosbag2 metadata version written (Jazzy's; later rosbag2 reads it)
STORAGES = ("mcap", "sqlite3")


class BagError(Exception):
    """The path is not a readable rosbag2 bag, or lacks what was asked for."""


def message_class(msgtype: str) -> type:
    """The rclpy message class of a ``pkg/msg/Name`` type string."""
    package, kind, name = msgtype.split("/")
    return getattr(importlib.import_module(f"{package}.{kind}"), name)


def _msg_dir() -> Path:
    try:
        from ament_index_python.packages import get_package_share_directory

        share = Path(get_package_share_directory("tactile_dock_ros")) / "msg"
        if share.is_dir():
            return share
    except (LookupError, OSError):  # not installed, or AMENT_PREFIX_PATH unset
        pass
    return Path(__file__).resolve().parents[2] / "msg"


def typestore():
    """rosbags type store: ROS 2 Kilted's standard types plus this package's messages."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    types = {}
    for path in sorted(_msg_dir().glob("*.msg")):
        types.update(get_types_from_msg(path.read_text(), f"tactile_dock_ros/msg/{path.stem}"))
    store.register(types)
    return store


def rosbags_qos(profile):
    """rclpy QoSProfile -> rosbags Qos (the same policies; durations as sec, nsec)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    def duration(d) -> QosTime:
        return QosTime(*divmod(d.nanoseconds, 10**9))

    return Qos(
        history=QosHistory[profile.history.name],
        depth=profile.depth,
        reliability=QosReliability[profile.reliability.name],
        durability=QosDurability[profile.durability.name],
        deadline=duration(profile.deadline),
        lifespan=duration(profile.lifespan),
        liveliness=QosLiveliness[profile.liveliness.name],
        liveliness_lease_duration=duration(profile.liveliness_lease_duration),
        avoid_ros_namespace_conventions=profile.avoid_ros_namespace_conventions,
    )


def write(
    path: Path,
    messages: Iterable[tuple[str, int, object]],
    storage: str = "mcap",
    offered: Mapping[str, list] | None = None,
) -> int:
    """Write ``(topic, receive time ns, rclpy message)`` triples, in order, to a new bag.

    Topic types are ``EPISODE_TOPICS``'s; ``storage`` one of ``STORAGES``; ``offered`` maps a
    topic to the rclpy QoS profiles its publishers offered (``EpisodeRecord.offered_qos``), the
    topic's ``QOS`` where it has none. Returns the number of messages written. The bag
    directory must not exist yet (rosbag2 never overwrites).
    """
    from rclpy.serialization import serialize_message
    from rosbags.rosbag2 import StoragePlugin, Writer, WriterError

    if storage not in STORAGES:
        raise BagError(f"storage {storage!r} is not one of {STORAGES}")
    store, count, connections = typestore(), 0, {}
    offered = offered or {}
    plugin = StoragePlugin[storage.upper()]
    try:
        with Writer(Path(path), version=BAG_VERSION, storage_plugin=plugin) as writer:
            for topic, stamp_ns, msg in messages:
                if topic not in connections:
                    if topic not in EPISODE_TOPICS:
                        raise BagError(f"topic {topic!r} is not one of {sorted(EPISODE_TOPICS)}")
                    profiles = offered.get(topic) or [QOS[topic]]
                    connections[topic] = writer.add_connection(
                        topic,
                        EPISODE_TOPICS[topic],
                        typestore=store,
                        offered_qos_profiles=[rosbags_qos(p) for p in profiles],
                    )
                writer.write(connections[topic], int(stamp_ns), serialize_message(msg))
                count += 1
    except WriterError as err:
        raise BagError(f"cannot write bag {path}: {err}") from err
    return count


def read(path: Path, topics: Iterable[str] = EPISODE_TOPICS) -> Iterator[tuple[str, int, object]]:
    """``(topic, receive time ns, rclpy message)`` of ``topics`` in the bag, in time order."""
    from rclpy.serialization import deserialize_message
    from rosbags.rosbag2 import Reader, ReaderError

    wanted = set(topics)
    if not (Path(path) / "metadata.yaml").is_file():
        raise BagError(f"{path} is not a rosbag2 bag directory (no metadata.yaml)")
    try:
        with Reader(Path(path)) as reader:
            connections = [c for c in reader.connections if c.topic in wanted]
            classes = {c.id: message_class(c.msgtype) for c in connections}
            if not connections:
                return
            for connection, stamp_ns, raw in reader.messages(connections=connections):
                try:
                    msg = deserialize_message(raw, classes[connection.id])
                except Exception as err:  # rclpy raises its RMWError on a definition mismatch
                    raise BagError(
                        f"{path}: cannot decode a {connection.msgtype} on {connection.topic}; "
                        f"recorded with another version of the message? ({err})"
                    ) from err
                yield connection.topic, stamp_ns, msg
    except ReaderError as err:
        raise BagError(f"cannot read bag {path}: {err}") from err
