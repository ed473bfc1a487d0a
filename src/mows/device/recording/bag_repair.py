"""Recovering a recording that was never closed: the driver killed (SIGKILL, power cut), the
disk full. ``mows bag repair DIR``.

A recording's MCAP file is written as a sequence of chunks (:class:`mows.device.recording.bags.Recording`
flushes each to disk as it closes); only a closed bag has the summary (chunk index, statistics)
and the ``metadata.yaml`` that readers need. :func:`salvage` reads the records of the data
section in file order, the way the MCAP specification lays them out, and keeps every chunk
that is whole (its length inside the file, its checksum right); it stops at the first record
cut short. :func:`repair` writes a new, closed bag from what was salvaged next to the damaged
file, which it keeps as ``NAME.mcap.damaged``: nothing is deleted.
"""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import struct
from pathlib import Path

import yaml
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.storage_mcap import decompress, get_qos
from rosbags.typesys import get_types_from_msg

from mows.device.recording import bags

OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_DATA_END = 0x03, 0x04, 0x05, 0x06, 0x0F
RECORD_HEADER = struct.Struct("<BQ")  # opcode, content length
SWAP = "swap.json"  # in the staging directory: the renames of the swap, written before them


@dataclasses.dataclass
class Salvage:
    """What the intact part of an MCAP file holds."""

    path: Path
    schemas: dict  # id → (name, encoding, definition text)
    channels: dict  # id → (schema id, topic, message encoding, metadata bytes)
    messages: list  # (channel id, log time ns, serialised data), in file order
    chunks: int  # whole chunks read
    intact_bytes: int  # the file is readable up to here
    size: int
    closed: bool  # the data section ended properly (a DataEnd record)
    problem: str = ""  # why reading stopped early
    written: int | None = None  # messages the recorder had written at its last flush, if known

    def summary(self) -> str:
        """How many messages were recovered and what was lost, in one sentence."""
        text = (
            f"{self.path}: recovered {len(self.messages)} messages on {len(self.channels)} topics "
            f"from {self.chunks} intact chunks"
        )
        if self.closed:
            return text + "; the data section is complete"
        lost = self.size - self.intact_bytes
        cut = (
            f"{lost} bytes at the end of the file ({self.problem})"
            if lost
            else "nothing on disk (the file ends after its last whole chunk)"
        )
        known = ""
        if self.written is not None:
            missing = self.written - len(self.messages)
            known = (
                f"; all {self.written} messages on disk at the recorder's last flush were recovered"
                if missing <= 0
                else f"; {missing} of the {self.written} messages on disk at the recorder's "
                "last flush are in a damaged chunk"
            )
        return f"{text}; lost: {cut}, and the messages the recorder held in memory (at most its last chunk){known}"


def _string(buffer: bytes, offset: int) -> tuple[str, int]:
    (length,) = struct.unpack_from("<I", buffer, offset)
    end = offset + 4 + length
    if end > len(buffer):
        raise ValueError("a string runs past its record")
    return buffer[offset + 4 : end].decode(), end


def _records(buffer: bytes, start: int, end: int):
    """(opcode, content, offset) of the whole records in ``buffer[start:end]``; stops with
    ValueError at a record cut short."""
    offset = start
    while offset < end:
        if offset + RECORD_HEADER.size > end:
            raise ValueError(f"a record header cut short at byte {offset}")
        op, length = RECORD_HEADER.unpack_from(buffer, offset)
        body_end = offset + RECORD_HEADER.size + length
        if body_end > end:
            raise ValueError(f"a record (opcode 0x{op:02x}, {length} bytes) cut short at byte {offset}")
        yield op, buffer[offset + RECORD_HEADER.size : body_end], offset
        offset = body_end


def _chunk_content(body: bytes) -> bytes:
    """The records of a chunk record, decompressed and checked against its CRC."""
    _, _, uncompressed_size, crc = struct.unpack_from("<QQQI", body, 0)
    compression, offset = _string(body, 28)
    (compressed_size,) = struct.unpack_from("<Q", body, offset)
    data = body[offset + 8 : offset + 8 + compressed_size]
    if len(data) != compressed_size:
        raise ValueError("chunk data shorter than its stated size")
    return decompress(data, compression, uncompressed_size, crc)


class _Collector:
    def __init__(self):
        self.schemas, self.channels, self.messages = {}, {}, []

    def add(self, op: int, body: bytes) -> None:
        if op == OP_SCHEMA:
            (key,) = struct.unpack_from("<H", body, 0)
            name, offset = _string(body, 2)
            encoding, offset = _string(body, offset)
            (length,) = struct.unpack_from("<I", body, offset)
            self.schemas[key] = (name, encoding, body[offset + 4 : offset + 4 + length].decode())
        elif op == OP_CHANNEL:
            key, schema_id = struct.unpack_from("<HH", body, 0)
            topic, offset = _string(body, 4)
            encoding, offset = _string(body, offset)
            (length,) = struct.unpack_from("<I", body, offset)
            self.channels[key] = (schema_id, topic, encoding, body[offset + 4 : offset + 4 + length])
        elif op == OP_MESSAGE:
            channel_id, _, log_time, _ = struct.unpack_from("<HIQQ", body, 0)
            self.messages.append((channel_id, log_time, body[22:]))


def salvage(path) -> Salvage:
    """Every schema, channel and message in the whole chunks of the MCAP file ``path``."""
    path = Path(path)
    data = path.read_bytes()
    if not data.startswith(bags.MCAP_MAGIC):
        raise bags.BagError(f"{path} is not an MCAP file (its first bytes are not the MCAP magic)")
    collected, chunks, intact, closed, problem = _Collector(), 0, len(bags.MCAP_MAGIC), False, ""
    try:
        for op, body, offset in _records(data, len(bags.MCAP_MAGIC), len(data)):
            if op == OP_DATA_END:
                closed = True
                break
            if op == OP_CHUNK:
                content = _chunk_content(body)  # whole before any of it is used
                inner = _Collector()
                for inner_op, inner_body, _ in _records(content, 0, len(content)):
                    inner.add(inner_op, inner_body)
                collected.schemas.update(inner.schemas)
                collected.channels.update(inner.channels)
                collected.messages += inner.messages
                chunks += 1
            else:
                collected.add(op, body)
            intact = offset + RECORD_HEADER.size + len(body)
    except (ValueError, ReaderError, struct.error, UnicodeDecodeError) as error:
        problem = str(error)
    return Salvage(
        path, collected.schemas, collected.channels, collected.messages, chunks, intact, len(data), closed, problem
    )


def _metadata(directory: Path) -> dict:
    """The bag's rosbag2_bagfile_information, {} when missing or unreadable."""
    try:
        info = yaml.safe_load((directory / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    except (OSError, yaml.YAMLError, KeyError, TypeError):
        return {}
    return info if isinstance(info, dict) else {}


def _mcap_of(directory: Path, info: dict) -> Path:
    listed = [directory / name for name in info.get("relative_file_paths") or []]
    candidates = [p for p in listed if p.is_file()] or sorted(directory.glob("*.mcap"))
    if len(candidates) != 1:
        raise bags.BagError(
            f"{directory}: expected one .mcap file to repair, found {[p.name for p in candidates] or 'none'}"
        )
    return candidates[0]


def _written(info: dict) -> int | None:
    value = (info.get("custom_data") or {}).get(bags.WRITTEN_MARK)
    return int(value) if isinstance(value, str) and value.isdigit() else None


def _free_name(path: Path) -> Path:
    candidate, number = path, 1
    while candidate.exists():
        candidate = path.with_name(f"{path.name}.{number}")
        number += 1
    return candidate


def repair(directory) -> Salvage:
    """Rebuild the bag in ``directory`` from the intact chunks of its MCAP file: a new closed
    MCAP and ``metadata.yaml``; the old file is kept as ``NAME.mcap.damaged``. A bag that
    reads already is left alone (:class:`bags.BagError` says so). The rebuilt bag is written in
    ``.DIR.repairing`` beside the bag and swapped in at the end; a repair killed meanwhile is
    undone by the next one, which then does the whole job."""
    directory = Path(directory)
    if not directory.is_dir():
        raise bags.BagError(f"{directory} is not a bag directory")
    staging = directory.parent / f".{directory.name}.repairing"
    if staging.is_dir():
        _undo_interrupted(staging)
    info = _metadata(directory)
    mcap = _mcap_of(directory, info)
    try:
        bags.check_readable(directory)
    except bags.BagError:
        pass
    else:
        raise bags.BagError(f"{directory} reads as it is: nothing to repair")
    found = dataclasses.replace(salvage(mcap), written=_written(info))
    if not found.channels:
        raise bags.BagError(
            f"{mcap}: no intact chunk holds the topics ({found.problem or 'empty'}): nothing can be recovered"
        )
    try:
        rebuilt = _write(found, staging / mcap.stem)
        damaged = _free_name(mcap.with_name(mcap.name + ".damaged"))
        new_mcap = rebuilt / f"{mcap.stem}.mcap"
        _write_swap(staging, {"mcap": str(mcap), "damaged": str(damaged), "new": str(new_mcap)})
        mcap.rename(damaged)
        shutil.move(str(new_mcap), str(mcap))
        (rebuilt / "metadata.yaml").replace(directory / "metadata.yaml")
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return found


def _write_swap(staging: Path, swap: dict) -> None:
    """What the swap of the rebuilt bag for the damaged one is about to rename, on disk first."""
    with open(staging / SWAP, "w", encoding="utf-8") as handle:
        json.dump(swap, handle)
        handle.flush()
        os.fsync(handle.fileno())


def _undo_interrupted(staging: Path) -> None:
    """The bag as it was before a repair that was killed (its staging directory is still there):
    a swap cut short is turned back (the damaged file under its own name again, the rebuilt one
    it had moved in removed), so that this repair starts from the killed recording. A swap that
    had ended (the rebuilt metadata moved in too) is kept."""
    try:
        swap = json.loads((staging / SWAP).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        swap = None  # killed before the swap began: the bag is untouched
    if swap is not None and (Path(swap["new"]).parent / "metadata.yaml").exists():
        mcap, damaged = Path(swap["mcap"]), Path(swap["damaged"])
        if damaged.exists():
            if not Path(swap["new"]).exists():
                mcap.unlink(missing_ok=True)  # the rebuilt file, moved in before the kill
            damaged.rename(mcap)
    shutil.rmtree(staging, ignore_errors=True)


def _write(found: Salvage, path: Path) -> Path:
    store = bags.typestore()
    connections = {}
    with bags.JazzyWriter(path) as writer:
        for key, (schema_id, topic, encoding, metadata) in sorted(found.channels.items()):
            msgtype, _, definition = found.schemas.get(schema_id, ("", "", ""))
            if msgtype not in store.types:  # a type of another package: its definition travels in the file
                store.register(get_types_from_msg(definition, msgtype))
            connections[key] = writer.add_connection(
                topic, msgtype, typestore=store, serialization_format=encoding, offered_qos_profiles=get_qos(metadata)
            )
        for channel_id, log_time, data in sorted(found.messages, key=lambda m: m[1]):
            if channel_id in connections:
                writer.write(connections[channel_id], log_time, data)
    return path
