"""What an MCAP file says about its writer, read by the MCAP specification alone
(https://mcap.dev/spec), independently of rosbags and of mows.device.recording.bags: the Header record's
profile and library, and the Metadata records' names and key-value maps.

A file is the magic, then records (opcode: uint8, content length: uint64, content), the last
one the Footer, then the magic again. Strings are a uint32 byte length and UTF-8 bytes; a map
is a uint32 byte length and its key and value strings one after the other.
"""

import struct
from pathlib import Path

import yaml

MAGIC = b"\x89MCAP0\r\n"
HEADER, FOOTER, METADATA = 0x01, 0x02, 0x0C


def records(path: Path) -> list[tuple[int, bytes]]:
    """(opcode, content) of every top-level record of the file, up to its Footer."""
    data = path.read_bytes()
    assert data[: len(MAGIC)] == MAGIC and data[-len(MAGIC) :] == MAGIC, f"{path} is not a closed MCAP file"
    found, offset = [], len(MAGIC)
    while True:
        opcode, length = struct.unpack_from("<BQ", data, offset)
        offset += 9
        found.append((opcode, data[offset : offset + length]))
        offset += length
        if opcode == FOOTER:
            assert offset == len(data) - len(MAGIC), "bytes between the Footer and the closing magic"
            return found


def string(content: bytes, offset: int) -> tuple[str, int]:
    """The string at ``offset`` and the offset after it."""
    (length,) = struct.unpack_from("<I", content, offset)
    return content[offset + 4 : offset + 4 + length].decode(), offset + 4 + length


def header(path: Path) -> tuple[str, str]:
    """(profile, library) of the Header, the first record."""
    opcode, content = records(path)[0]
    assert opcode == HEADER, f"the first record of {path} is opcode {opcode:#04x}, not the Header"
    profile, offset = string(content, 0)
    library, _ = string(content, offset)
    return profile, library


def metadata(path: Path) -> list[tuple[str, dict[str, str]]]:
    """(name, map) of every Metadata record."""
    found = []
    for opcode, content in records(path):
        if opcode == METADATA:
            name, offset = string(content, 0)
            (length,) = struct.unpack_from("<I", content, offset)
            offset, end, pairs = offset + 4, offset + 4 + length, {}
            while offset < end:
                key, offset = string(content, offset)
                pairs[key], offset = string(content, offset)
            found.append((name, pairs))
    return found


def assert_jazzy(bag: Path) -> None:
    """The bag directory says Jazzy where rosbag2 on Jazzy does: ``ros_distro`` in its
    metadata.yaml and in the serialized_metadata of its MCAP file's one ``rosbag2`` Metadata
    record, and the Header's profile ros2 and a library naming rosbag2 on Jazzy."""
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["ros_distro"] == "jazzy"
    (mcap,) = bag.glob("*.mcap")
    profile, library = header(mcap)
    assert profile == "ros2" and library.startswith("rosbag2.jazzy "), (profile, library)
    ((name, pairs),) = metadata(mcap)
    serialized = yaml.safe_load(pairs["serialized_metadata"])
    assert name == "rosbag2" and serialized["ros_distro"] == "jazzy"
    assert serialized["message_count"] == info["message_count"]  # the same bag's metadata
