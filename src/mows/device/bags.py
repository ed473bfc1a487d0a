"""rosbag2 bags (MCAP storage) written and read with ``rosbags``: no ROS install needed.

The mows_msgs types are registered from their .msg/.srv/.action text, found in the built
workspace (``share/mows_msgs`` under AMENT_PREFIX_PATH) or else in the repository's
``mows_msgs/`` package. Services and actions are split into their message parts the way
rosbag2 names them: ``mows_msgs/srv/RunCycle_Request``, ``mows_msgs/action/RotationSweep_Goal``.
Bags are written in the layout of Jazzy's ``ros2 bag`` (metadata version 9, MCAP storage) and
carry their message definitions.
"""
import functools
import os
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, Literal, NamedTuple

from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

PACKAGE = "mows_msgs"
REPOSITORY_PACKAGE = Path(__file__).resolve().parents[3] / PACKAGE
BAG_VERSION: Literal[9] = 9  # rosbag2's metadata version in Jazzy

# The parts of a service or action definition, in the order they appear between `---` lines.
PARTS = {
    "msg": ("",),
    "srv": ("_Request", "_Response"),
    "action": ("_Goal", "_Result", "_Feedback"),
}


class BagMessage(NamedTuple):
    topic: str
    msgtype: str  # e.g. mows_msgs/msg/RingdownFit
    timestamp_ns: int
    message: Any  # a rosbags message object of msgtype


def interface_directory() -> Path:
    """``share/mows_msgs`` of the first AMENT_PREFIX_PATH entry that has it, else the
    repository's ``mows_msgs/``."""
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidate = Path(prefix) / "share" / PACKAGE
        if (candidate / "msg").is_dir():
            return candidate
    if (REPOSITORY_PACKAGE / "msg").is_dir():
        return REPOSITORY_PACKAGE
    raise FileNotFoundError(
        f"no {PACKAGE} interface definitions under AMENT_PREFIX_PATH nor in {REPOSITORY_PACKAGE}"
    )


def split_definition(text: str, kind: str) -> list[str]:
    """The message parts of one .msg, .srv or .action text (split at the `---` lines)."""
    parts: list[list[str]] = [[]]
    for line in text.splitlines():
        if line.strip() == "---":
            parts.append([])
        else:
            parts[-1].append(line)
    if len(parts) != len(PARTS[kind]):
        raise ValueError(f"a .{kind} definition has {len(PARTS[kind])} parts, found {len(parts)}")
    return ["\n".join(part) for part in parts]


def interface_types(directory: Path) -> dict[str, Any]:
    """Every message type defined in ``directory`` (msg/, srv/, action/), by rosbag2 name."""
    types: dict[str, Any] = {}
    for kind, suffixes in PARTS.items():
        for path in sorted((directory / kind).glob(f"*.{kind}")):
            parts = split_definition(path.read_text(), kind)
            for suffix, text in zip(suffixes, parts):
                name = f"{PACKAGE}/{kind}/{path.stem}{suffix}"
                # rosbags files names outside msg/ and action/ under msg/ (srv/msg/...):
                # keep the one definition it parsed, under rosbag2's name.
                (definition,) = get_types_from_msg(text, name).values()
                types[name] = definition
    return types


@functools.cache
def typestore() -> Typestore:
    """The Jazzy typestore with the mows_msgs types added."""
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(interface_types(interface_directory()))
    return store


def write_bag(path: str | os.PathLike, messages: Iterable[BagMessage]) -> Path:
    """Write ``messages`` to a new rosbag2 bag directory at ``path`` (MCAP storage).

    A connection is opened for each (topic, msgtype) on its first message. ``path`` must
    not exist yet.
    """
    store = typestore()
    connections = {}
    with Writer(Path(path), version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP) as writer:
        for topic, msgtype, timestamp_ns, message in messages:
            key = (topic, msgtype)
            if key not in connections:
                connections[key] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(connections[key], timestamp_ns, store.serialize_cdr(message, msgtype))
    return Path(path)


def read_bag(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """The messages of the bag at ``path`` in time order, optionally only of ``topics``.

    Messages are decoded with ``typestore()`` (Jazzy and mows_msgs types), not with rosbags'
    AnyReader: AnyReader files a definition named ``pkg/srv/Name_Request`` under
    ``pkg/srv/msg/`` and then cannot open a bag that holds service parts.
    """
    store = typestore()
    with Reader(Path(path)) as reader:
        wanted = set(topics) if topics is not None else None
        connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
        if not connections:  # rosbags reads every connection when given none
            return
        for connection, timestamp_ns, raw in reader.messages(connections=connections):
            yield BagMessage(
                connection.topic,
                connection.msgtype,
                timestamp_ns,
                store.deserialize_cdr(raw, connection.msgtype),
            )
