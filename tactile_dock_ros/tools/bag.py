"""ROS 2 bags (rosbag2, MCAP or sqlite3 storage) of an episode's topics, without rosbag2.

On the robot, record what ``tools.replay`` needs with::

    ros2 bag record /terrain_prior /contact_history /shape_samples /plan /execution_report \\
        /episode_status /sample_request

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

What rosbag2 writes and ``rosbags`` (0.11) does not, ``write`` adds (``_Rosbag2Writer``):

- ``ros_distro``: rosbag2 stores ``$ROS_DISTRO`` (empty when unset); rosbags stores ``rosbags``.
  Here: ``ROS_DISTRO`` when set, else the distro of the installed rclpy (``ros_distro``), in
  ``metadata.yaml``, the bag's own copy of it (the MCAP ``rosbag2`` metadata record, the sqlite3
  ``metadata`` table) and the sqlite3 ``schema`` table.
- Each topic's type hash (RIHS01) as rosbag2 writes it: ``type_description_hash`` of the topic's
  metadata and, for MCAP, the channel metadata key ``topic_type_hash``, which rosbag2's MCAP
  reader takes the topic's hash from (rosbags writes only ``offered_qos_profiles`` there). The
  hash is rosidl's own (``type_hash``), the one rclpy's publishers announce.
"""

from __future__ import annotations

import importlib
import io
import json
import os
import re
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from types import MappingProxyType

from tactile_dock_ros.nodes import qos
from tactile_dock_ros.nodes.common import MAX_HOLDS

# Topics (absolute names, default remappings) and their types, as the nodes publish them.
EPISODE_TOPICS = {
    "/terrain_prior": "tactile_dock_ros/msg/ShapeDistribution",
    "/contact_history": "tactile_dock_ros/msg/ContactHistory",
    "/shape_samples": "tactile_dock_ros/msg/ShapeSamples",
    "/plan": "tactile_dock_ros/msg/DockingPlan",
    "/execution_report": "tactile_dock_ros/msg/ExecutionReport",
    "/episode_status": "tactile_dock_ros/msg/EpisodeStatus",
    "/sample_request": "tactile_dock_ros/msg/SampleRequest",  # the planner's give-up check
}
# The QoS each topic is published with (nodes.qos; perception's default max_holds): what a bag
# offers when it is played.
QOS = {
    "/terrain_prior": qos.priors(MAX_HOLDS.default),
    "/contact_history": qos.LATCHED,
    "/shape_samples": qos.LATCHED,
    "/plan": qos.EVENTS,
    "/execution_report": qos.REPORTS,
    "/episode_status": qos.LATCHED,
    "/sample_request": qos.EVENTS,
}
BAG_VERSION = 9  # rosbag2 metadata version written (Jazzy's; later rosbag2 reads it)
# rclpy's major version in each ROS 2 distro (its package.xml; e.g. the PyPI wheels ros-rclpy
# 7.1.x are Jazzy's, 9.1.x Kilted's): the distro when ROS_DISTRO is not set.
RCLPY_DISTROS = {3: "humble", 4: "iron", 7: "jazzy", 9: "kilted"}
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


def _share(package: str) -> Path | None:
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(package))
    except (ImportError, LookupError, OSError):  # not installed, or AMENT_PREFIX_PATH unset
        return None


def rclpy_version() -> str | None:
    """The installed rclpy's version: its package.xml (ament index: apt installs and the PyPI
    wheels alike), else the ``ros-rclpy`` wheel's metadata; None if neither is found."""
    share = _share("rclpy")
    if share is not None:
        found = re.search(
            r"<version>\s*([^<\s]+)\s*</version>", (share / "package.xml").read_text()
        )
        if found:
            return found.group(1)
    try:
        from importlib.metadata import PackageNotFoundError, version

        return version("ros-rclpy")
    except PackageNotFoundError:
        return None


def ros_distro() -> str:
    """The ROS 2 distro a written bag names: ``ROS_DISTRO`` when set (what rosbag2 stores), else
    the installed rclpy's (``RCLPY_DISTROS`` by major version: the PyPI wheels set no
    ``ROS_DISTRO``), else "" (as rosbag2 with ``ROS_DISTRO`` unset)."""
    if os.environ.get("ROS_DISTRO"):
        return os.environ["ROS_DISTRO"]
    version = rclpy_version()
    major = version.split(".")[0] if version else ""
    return RCLPY_DISTROS.get(int(major), "") if major.isdigit() else ""


def type_hash(msgtype: str, store=None) -> str:
    """RIHS01 hash of a ``pkg/msg/Name`` type as rosidl computed it at build time: the
    ``type_hashes`` of the installed ``share/<pkg>/msg/<Name>.json``
    (rosidl_generator_type_description; the C typesupport, and so the hash rclpy's publishers
    announce, is generated from it). Where that file is missing (Humble has none; a package not
    installed), rosbags' hash of the definition in ``store`` (it computes the same)."""
    package, kind, name = msgtype.split("/")
    share = _share(package)
    if share is not None:
        try:
            document = json.loads((share / kind / f"{name}.json").read_text())
            for entry in document["type_hashes"]:
                if entry["type_name"] == msgtype:
                    return entry["hash_string"]
        except (OSError, ValueError, KeyError, TypeError):
            pass
    return (store or typestore()).hash_rihs01(msgtype)


def _rosbag2_writer(distro: str):
    """rosbags' ``Writer`` that writes ``distro`` as the bag's ROS distro and, in MCAP, each
    channel's ``topic_type_hash`` (the connection's RIHS01 digest), as rosbag2 does."""
    import yaml
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.storage_mcap import McapWriter, write_channel, write_string
    from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

    def with_distro(metadata: str) -> str:  # the serialized metadata a storage file holds
        information = yaml.safe_load(metadata)
        information["ros_distro"] = distro
        return yaml.safe_dump(information, sort_keys=False).strip()

    class Mcap(McapWriter):
        def add_connection(self, connection, offered_qos_profiles: str) -> None:
            start = self.chunk.bio.tell()
            super().add_connection(connection, offered_qos_profiles)
            extra = io.BytesIO()
            write_string(extra, "topic_type_hash")
            write_string(extra, connection.digest)
            channel = self.channels[-1]
            self.channels[-1] = channel._replace(metadata=channel.metadata + extra.getvalue())
            self.chunk.bio.seek(start)  # rewrite the channel record just written
            self.chunk.bio.truncate()
            write_channel(self.chunk.bio, self.channels[-1], self.schemas)

        def close(self, version: int, metadata: str) -> None:
            super().close(version, with_distro(metadata))

    class Sqlite3(Sqlite3Writer):
        def close(self, version: int, metadata: str) -> None:
            self.cursor.execute("UPDATE schema SET ros_distro = ?", (distro,))
            super().close(version, with_distro(metadata))

    class Rosbag2Writer(Writer):
        STORAGE_PLUGINS = MappingProxyType(
            {StoragePlugin.MCAP: Mcap, StoragePlugin.SQLITE3: Sqlite3}
        )

        def close(self) -> None:
            super().close()
            document = yaml.safe_load(self.metapath.read_text())
            document["rosbag2_bagfile_information"]["ros_distro"] = distro
            self.metapath.write_text(yaml.safe_dump(document, sort_keys=False))

    return Rosbag2Writer


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
    from rosbags.rosbag2 import StoragePlugin, WriterError

    if storage not in STORAGES:
        raise BagError(f"storage {storage!r} is not one of {STORAGES}")
    store, count, connections = typestore(), 0, {}
    offered = offered or {}
    plugin = StoragePlugin[storage.upper()]
    try:
        writer_class = _rosbag2_writer(ros_distro())
        with writer_class(Path(path), version=BAG_VERSION, storage_plugin=plugin) as writer:
            for topic, stamp_ns, msg in messages:
                if topic not in connections:
                    if topic not in EPISODE_TOPICS:
                        raise BagError(f"topic {topic!r} is not one of {sorted(EPISODE_TOPICS)}")
                    profiles = offered.get(topic) or [QOS[topic]]
                    msgtype = EPISODE_TOPICS[topic]
                    connections[topic] = writer.add_connection(
                        topic,
                        msgtype,
                        msgdef=store.generate_msgdef(msgtype, ros_version=2)[0],
                        rihs01=type_hash(msgtype, store),
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
