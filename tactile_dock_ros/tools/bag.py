"""ROS 2 bags (rosbag2, sqlite3 storage) of an episode's topics, without the rosbag2 packages.

On the robot, record what ``tools.replay`` needs with::

    ros2 bag record /terrain_prior /contact_history /shape_samples /plan /execution_report \\
        /episode_status

PyPI has no rosbag2, so here the pure-Python ``rosbags`` library reads and writes the same
format, and rclpy (de)serializes the messages (CDR): a bag written here plays with ``ros2 bag
play``, and a bag recorded on a robot reads here. Message definitions for the bag's metadata
come from this package's installed ``share/tactile_dock_ros/msg`` (the source tree's ``msg/``
when the package is not installed).
"""

from __future__ import annotations

import importlib
from collections.abc import Iterable, Iterator
from pathlib import Path

# Topics (absolute names, default remappings) and their types, as the nodes publish them.
EPISODE_TOPICS = {
    "/terrain_prior": "tactile_dock_ros/msg/ShapeDistribution",
    "/contact_history": "tactile_dock_ros/msg/ContactHistory",
    "/shape_samples": "tactile_dock_ros/msg/ShapeSamples",
    "/plan": "tactile_dock_ros/msg/DockingPlan",
    "/execution_report": "tactile_dock_ros/msg/ExecutionReport",
    "/episode_status": "diagnostic_msgs/msg/DiagnosticStatus",
}
BAG_VERSION = 8  # rosbag2 metadata version written (Jazzy's; Kilted reads it too)


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


def write(path: Path, messages: Iterable[tuple[str, int, object]]) -> int:
    """Write ``(topic, receive time ns, rclpy message)`` triples, in order, to a new bag.

    Topic types are ``EPISODE_TOPICS``'s; returns the number of messages written. The bag
    directory must not exist yet (rosbag2 never overwrites).
    """
    from rclpy.serialization import serialize_message
    from rosbags.rosbag2 import Writer, WriterError

    store, count, connections = typestore(), 0, {}
    try:
        with Writer(Path(path), version=BAG_VERSION) as writer:
            for topic, stamp_ns, msg in messages:
                if topic not in connections:
                    if topic not in EPISODE_TOPICS:
                        raise BagError(f"topic {topic!r} is not one of {sorted(EPISODE_TOPICS)}")
                    connections[topic] = writer.add_connection(
                        topic, EPISODE_TOPICS[topic], typestore=store
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
