"""rosbag2 bags (MCAP storage) written and read with ``rosbags``: no ROS install needed.

The mows_msgs types are registered from their .msg/.srv/.action text, found in the built
workspace (``share/mows_msgs`` under AMENT_PREFIX_PATH) or else in the repository's
``mows_msgs/`` package. Services and actions are split into their message parts the way
rosbag2 names them: ``mows_msgs/srv/RunCycle_Request``, ``mows_msgs/action/RotationSweep_Goal``.
Bags are written in the layout of Jazzy's ``ros2 bag`` (metadata version 9, MCAP storage) and
carry their message definitions. Where rosbags writes its own name, they say Jazzy, as rosbag2
does (:class:`JazzyWriter`): ``ros_distro`` in ``metadata.yaml`` and in the MCAP file's
``rosbag2`` metadata record, and the MCAP Header's library string. A :class:`Recording`
survives a kill: its ``metadata.yaml`` is there from the start and every chunk is on disk
once it closes, so that :mod:`mows.device.recording.bag_repair` rebuilds all but the last chunk. A bag
that cannot be read raises :class:`BagError`, which says what is wrong and, for a recording
never closed, how to repair it.
"""

import functools
import importlib.metadata
import os
import struct
from collections.abc import Callable, Iterable, Iterator
from io import BytesIO
from pathlib import Path
from typing import Any, Literal, NamedTuple, cast

import numpy as np
import yaml
from rosbags.interfaces import Connection, MessageDefinitionFormat, Nodetype, Qos
from rosbags.rosbag2 import Reader, ReaderError, StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.metadata import dump_qos_v9
from rosbags.rosbag2.storage_mcap import McapWriter, write_record, write_string
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from mows.records.files import read_input

PACKAGE = "mows_msgs"
REPOSITORY_PACKAGE = Path(__file__).resolve().parents[4] / PACKAGE
BAG_VERSION: Literal[9] = 9  # rosbag2's metadata version in Jazzy
ROS_DISTRO = "jazzy"  # what rosbag2 writes as ros_distro; rosbags writes its own name
MCAP_MAGIC = b"\x89MCAP0\r\n"  # the first and last bytes of an MCAP file (MCAP specification)
MCAP_HEADER = 0x01  # the opcode of the Header record, which follows the opening magic
MCAP_PROFILE = "ros2"  # the Header's profile: the rosbag2 conventions
# The Header's library is free text naming the writer. rosbag2 leaves libmcap's default there
# ("libmcap 1.x.y"); ours is not libmcap, so it names the layout and distribution it follows,
# then what wrote it.
MCAP_LIBRARY = f"rosbag2.{ROS_DISTRO} (mows, rosbags-{importlib.metadata.version('rosbags')})"

# The parts of a service or action definition, in the order they appear between `---` lines.
PARTS = {
    "msg": ("",),
    "srv": ("_Request", "_Response"),
    "action": ("_Goal", "_Result", "_Feedback"),
}


# custom_data keys of a recording's metadata.yaml while it is open
OPEN_MARK, WRITTEN_MARK = "mows_recording", "mows_messages_written"


class BagError(ValueError):
    """A bag that cannot be read or written, with the reason and what to do."""


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
    raise FileNotFoundError(f"no {PACKAGE} interface definitions under AMENT_PREFIX_PATH nor in {REPOSITORY_PACKAGE}")


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
            if not path.exists():  # a symlink-install's link to a definition since renamed or removed
                continue
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


def write_bag(path: str | os.PathLike, messages: Iterable[BagMessage], store: Typestore | None = None) -> Path:
    """Write ``messages`` to a new rosbag2 bag directory at ``path`` (MCAP storage), with the
    definitions of ``store`` (default :func:`typestore`).

    A connection is opened for each (topic, msgtype) on its first message. ``path`` must
    not exist yet.
    """
    store = typestore() if store is None else store
    connections = {}
    with JazzyWriter(path) as writer:
        for topic, msgtype, timestamp_ns, message in messages:
            key = (topic, msgtype)
            if key not in connections:
                connections[key] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(connections[key], timestamp_ns, store.serialize_cdr(message, msgtype))
    return Path(path)


def check_readable(path: str | os.PathLike) -> Path:
    """``path`` if rosbags can open it as a bag, else :class:`BagError` in words: not there, a
    directory that is no bag, or a recording never closed (``mows bag repair``)."""
    path = Path(path)
    if not path.exists():
        raise BagError(f"{path} does not exist")
    if path.is_dir() and not (path / "metadata.yaml").is_file():
        if not any(path.glob("*.mcap")):
            raise BagError(
                f"{path} is a directory but not a rosbag2 bag (no metadata.yaml, no .mcap file): "
                "give a bag directory, an .mcap file or a CSV table"
            )
        raise BagError(
            f"{path} has no metadata.yaml: the recording was never closed; "
            f"`mows bag repair {path}` recovers its intact chunks"
        )
    metadata = path / "metadata.yaml" if path.is_dir() else None
    if metadata is not None and metadata.is_file():
        try:
            metadata.read_text(encoding="utf-8")
        except UnicodeDecodeError as error:
            raise BagError(
                f"{metadata} is not UTF-8 text (byte {error.start}): not rosbag2's metadata; "
                f"restore it, or `mows bag repair {path}` rebuilds the bag from its .mcap file"
            ) from None
    try:
        with Reader(path):
            pass
    except (ReaderError, *READER_FAULTS) as error:
        raise _unreadable(path, error) from None
    return path


# What rosbags raises, besides its ReaderError, on a file that is not what it expects (a file of
# only MCAP's magic: TypeError from ord() of nothing).
READER_FAULTS = (ValueError, TypeError, KeyError, IndexError, AttributeError, struct.error, EOFError, yaml.YAMLError)


def _unreadable(path: Path, error: Exception) -> BagError:
    bag = path if path.is_dir() else path.parent
    problem = " ".join(str(error).split()) or type(error).__name__
    return BagError(
        f"{path} cannot be read as a bag ({problem}): if the recording was cut off, "
        f"`mows bag repair {bag}` recovers its intact chunks"
    )


def as_jazzy(metadata_yaml: str) -> str:
    """rosbags' serialised bag metadata with rosbag2's ``ros_distro`` in place of rosbags' name."""
    return metadata_yaml.replace("ros_distro: rosbags", f"ros_distro: {ROS_DISTRO}")


class JazzyMcapWriter(McapWriter):
    """rosbags' MCAP storage, saying Jazzy where rosbags says rosbags: the Header's library
    (:data:`MCAP_LIBRARY`) and the ``ros_distro`` of the ``serialized_metadata`` in the
    ``rosbag2`` Metadata record, which is where rosbag2 on Jazzy keeps it."""

    def __init__(self, path: Path, compression: CompressionMode) -> None:
        super().__init__(path, compression)
        # rosbags has written the magic and its Header, and nothing else yet (the schemas and
        # channels wait in the first chunk): the Header is rewritten in place.
        self.bio.seek(len(MCAP_MAGIC))
        self.bio.truncate()
        header = BytesIO()
        write_string(header, MCAP_PROFILE)
        write_string(header, MCAP_LIBRARY)
        write_record(self.bio, MCAP_HEADER, header)

    def close(self, version: int, metadata: str) -> None:
        super().close(version, as_jazzy(metadata))


class JazzyWriter(Writer):
    """A rosbags writer of a new bag at ``path`` in Jazzy's layout (metadata version 9, MCAP
    storage) that says Jazzy in its ``metadata.yaml`` and its MCAP file, as rosbag2 does."""

    STORAGE_PLUGINS = {**Writer.STORAGE_PLUGINS, StoragePlugin.MCAP: JazzyMcapWriter}

    def __init__(self, path: str | os.PathLike):
        super().__init__(Path(path), version=BAG_VERSION, storage_plugin=StoragePlugin.MCAP)

    def close(self) -> None:
        super().close()
        self.metapath.write_text(as_jazzy(self.metapath.read_text()))


def read_bag(path: str | os.PathLike, topics: Iterable[str] | None = None) -> Iterator[BagMessage]:
    """The messages of the bag at ``path`` in time order, optionally only of ``topics``.

    Messages are decoded with ``typestore()`` (Jazzy and mows_msgs types), not with rosbags'
    AnyReader: AnyReader files a definition named ``pkg/srv/Name_Request`` under
    ``pkg/srv/msg/`` and then cannot open a bag that holds service parts.
    """
    store = typestore()
    path = check_readable(read_input(path))
    try:
        with Reader(path) as reader:
            wanted = set(topics) if topics is not None else None
            connections = [c for c in reader.connections if wanted is None or c.topic in wanted]
            if not connections:  # rosbags reads every connection when given none
                return
            decoders = {c.id: decoder(c, store) for c in connections}
            for connection, timestamp_ns, raw in reader.messages(connections=connections):
                yield BagMessage(connection.topic, connection.msgtype, timestamp_ns, decoders[connection.id](raw))
    except BagError:
        raise
    except (ReaderError, *READER_FAULTS) as error:  # a bag damaged past its opening
        raise _unreadable(path, error) from None


def decoder(connection: Connection, store: Typestore) -> Callable[[bytes], Any]:
    """CDR bytes of ``connection`` → a message of ``store``'s definition of its type.

    A bag recorded with an earlier mows_msgs carries that earlier definition (rosbag2 stores
    each topic's). Its messages are decoded with it and then given the fields it lacked at
    their zero value, which every added field of mows_msgs keeps meaning what the earlier
    messages meant (a new ``probe_id`` is 0: the one probe there was).
    """
    msgtype = connection.msgtype
    recorded = recorded_types(connection)
    if not recorded or all(
        store.fielddefs.get(name, (None, None))[1] == fields for name, (_, fields) in recorded.items()
    ):
        return functools.partial(deserialize_cdr, store, msgtype)
    earlier = get_typestore(Stores.ROS2_JAZZY)
    earlier.register(recorded)
    return lambda raw: upgraded(deserialize_cdr(earlier, msgtype, raw), msgtype, store)


# rclpy's serialized messages can run past their last field by up to one 8-byte alignment unit
# (a message ending in an empty float64[] does), which rosbags' own size check (≤ 3 bytes) refuses.
TRAILING_BYTES = 8


def deserialize_cdr(store: Typestore, msgtype: str, raw: bytes) -> Any:
    """The ``msgtype`` message of the CDR bytes ``raw`` (the 4-byte encapsulation header first),
    unused bytes after its last field allowed up to TRAILING_BYTES. ValueError otherwise."""
    if len(raw) < 4 or bytes(raw[:2]) not in {b"\x00\x00", b"\x00\x01"}:
        raise ValueError(f"{msgtype}: invalid or unsupported CDR encapsulation")
    msgdef = store.get_msgdef(msgtype)
    decode = msgdef.deserialize_cdr_le if raw[1] else msgdef.deserialize_cdr_be
    try:
        message, end = decode(raw[4:], 0, msgdef.cls, store)
    except (struct.error, UnicodeDecodeError) as error:
        raise ValueError(f"{msgtype}: cannot decode: {error}") from None
    if len(raw) - 4 - end > TRAILING_BYTES:
        raise ValueError(f"{msgtype}: {len(raw) - 4 - end} bytes after the message's last field")
    return message


def recorded_types(connection: Connection) -> dict[str, Any]:
    """The types of the definition a bag stores for ``connection`` (empty when it has none)."""
    if connection.msgdef.format != MessageDefinitionFormat.MSG or not connection.msgdef.data:
        return {}
    msgtype = connection.msgtype
    types = dict(get_types_from_msg(connection.msgdef.data, msgtype))
    if msgtype not in types:  # rosbags files pkg/srv/Name under pkg/srv/msg/Name (interface_types)
        package, name = msgtype.split("/")[0], msgtype.rsplit("/", 1)[1]
        (filed,) = [key for key in types if key.startswith(f"{package}/") and key.endswith(f"/{name}")]
        types[msgtype] = types.pop(filed)
    return types


def upgraded(message: Any, msgtype: str, store: Typestore) -> Any:
    """``message``, decoded with an earlier definition of ``msgtype``, as ``store``'s: the fields
    it has are kept (nested messages upgraded too), those it lacks are zero."""
    values = {}
    detail: Any
    for name, (kind, detail) in store.fielddefs[msgtype][1]:
        if not hasattr(message, name):
            values[name] = zero(kind, detail, store)
        elif kind == Nodetype.NAME:
            values[name] = upgraded(getattr(message, name), detail, store)
        elif kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and detail[0][0] == Nodetype.NAME:
            values[name] = [upgraded(item, detail[0][1], store) for item in getattr(message, name)]
        else:
            values[name] = getattr(message, name)
    return store.types[msgtype](**values)


def zero(kind: Nodetype, detail: Any, store: Typestore) -> Any:
    """The zero value of a field of ``store``'s types: 0, 0.0, False, "", an empty sequence,
    an array of zeros, a message of zeros."""
    if kind == Nodetype.NAME:
        return store.types[detail](**{n: zero(k, d, store) for n, (k, d) in store.fielddefs[detail][1]})
    if kind == Nodetype.SEQUENCE:
        element_kind, element = detail[0]
        return np.zeros(0, element[0]) if element_kind == Nodetype.BASE and element[0] != "string" else []
    if kind == Nodetype.ARRAY:
        (element_kind, element), length = detail
        return (
            [zero(element_kind, element, store) for _ in range(length)]
            if element_kind == Nodetype.NAME
            else (np.zeros(length, element[0]) if element[0] != "string" else [""] * length)
        )
    base = detail[0]
    return "" if base == "string" else False if base == "bool" else 0.0 if base.startswith("float") else 0


class Recording:
    """A new bag at ``path`` for ``topics`` ({name: (msgtype, [QoS])}) that a kill damages
    only at its end.

    rosbags' MCAP writer gathers messages into a chunk in memory and writes it when it passes
    1 MiB; the schemas and channels go into the first chunk. Here that first chunk is closed
    before any message (the topics are on disk at once), every later chunk is flushed and
    fsynced as soon as rosbags writes it, and a ``metadata.yaml`` marking the recording as
    open is written at the start (replaced by the writer's full one at :meth:`close`). A SIGKILL
    thus loses at most the chunk in memory (≤ 1 MiB, ~3 s of the 20 kS/s stream).
    """

    def __init__(self, path: str | os.PathLike, topics: dict[str, tuple[str, list[Qos]]]):
        self.path = Path(path)
        if self.path.exists() or self.path.is_symlink():
            raise BagError(f"{self.path} exists: a recording goes to a new path (nothing is overwritten)")
        self.messages = 0
        self._writer = JazzyWriter(self.path)
        self._writer.open()
        store = typestore()
        self._connections = {
            topic: self._writer.add_connection(topic, msgtype, typestore=store, offered_qos_profiles=qos)
            for topic, (msgtype, qos) in topics.items()
        }
        self._storage = cast(McapWriter, self._writer.storage)  # rosbags' internals (the pinned 0.11.9)
        self._topics = topics
        self._storage.close_chunk()
        self._flush()

    def write(self, topic: str, raw: bytes, timestamp_ns: int) -> None:
        """One serialised (CDR) message."""
        self._writer.write(self._connections[topic], timestamp_ns, raw)
        self.messages += 1
        if len(self._storage.chunks) != self._flushed_chunks:
            self._flush()

    def close(self) -> None:
        self._writer.close()

    def _flush(self) -> None:
        """The chunks written so far on disk, and the count of messages so far in the metadata."""
        self._storage.bio.flush()
        os.fsync(self._storage.bio.fileno())
        self._flushed_chunks = len(self._storage.chunks)
        self._write_open_metadata(self._topics)

    def _write_open_metadata(self, topics) -> None:
        """rosbag2's metadata with no counts yet, flagged open in ``custom_data`` with the number
        of messages written so far (what a repair compares its recovered count with)."""
        name = Path(self._storage.path).name
        info = {
            "version": BAG_VERSION,
            "storage_identifier": "mcap",
            "relative_file_paths": [name],
            "duration": {"nanoseconds": 0},
            "starting_time": {"nanoseconds_since_epoch": 0},
            "message_count": 0,
            "topics_with_message_count": [
                {
                    "topic_metadata": {
                        "name": topic,
                        "type": msgtype,
                        "serialization_format": "cdr",
                        "offered_qos_profiles": dump_qos_v9(qos),
                        "type_description_hash": self._connections[topic].digest,
                    },
                    "message_count": 0,
                }
                for topic, (msgtype, qos) in topics.items()
            ],
            "compression_format": "",
            "compression_mode": "",
            "files": [
                {
                    "path": name,
                    "starting_time": {"nanoseconds_since_epoch": 0},
                    "duration": {"nanoseconds": 0},
                    "message_count": 0,
                }
            ],
            "custom_data": {
                OPEN_MARK: "open: counts are written at close; after a kill run mows bag repair",
                WRITTEN_MARK: str(self.messages),
            },
            "ros_distro": ROS_DISTRO,
        }
        temporary = self.path / "metadata.yaml.tmp"
        temporary.write_text(yaml.safe_dump({"rosbag2_bagfile_information": info}, sort_keys=False))
        temporary.replace(self.path / "metadata.yaml")
