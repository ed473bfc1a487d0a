"""The serial frame codec of the MOWS device link (docs/serial_protocol.md).

A frame, little-endian::

    offset  size  field
    0       2     sync word A5 5A
    2       1     protocol version (1)
    3       1     frame type
    4       2     payload length N, bytes (at most MAX_PAYLOAD_BYTES)
    6       4     sequence number: the sender's frame counter, +1 per frame, wraps at 2**32
    10      8     timestamp, ns: the device clock in frames from the device, the host's
                  monotonic clock in frames from the host
    18      N     payload (its layout depends on the type: the ``Body`` classes of ``payloads``)
    18+N    4     CRC-32 (zlib/IEEE 802.3) of bytes 2 … 18+N−1 (everything after the sync word)

:class:`FrameDecoder` is incremental and never raises on data: it finds frames in any byte
stream, returns only frames whose CRC and payload check out, and counts what it throws away
(rejected candidates by reason, and discarded bytes), so that nothing disappears unseen.
"""

from __future__ import annotations

import dataclasses
import struct
import zlib
from collections import Counter

from mows.device.protocol.payloads import BODY_TYPES, Body, PayloadError

SYNC = b"\xa5\x5a"
VERSION = 1
HEADER = struct.Struct("<BBHIQ")  # version, type, length, sequence, timestamp_ns (after SYNC)
HEADER_BYTES = len(SYNC) + HEADER.size
CRC = struct.Struct("<I")
MAX_PAYLOAD_BYTES = 16384
SEQUENCE_MODULUS = 2**32

# Why a candidate frame was rejected (FrameDecoder.rejected keys).
REJECT_VERSION = "version"  # unknown protocol version
REJECT_LENGTH = "length"  # payload length above MAX_PAYLOAD_BYTES
REJECT_CRC = "crc"  # CRC mismatch: corrupted or not a frame at all
REJECT_TYPE = "type"  # CRC fine, frame type unknown
REJECT_PAYLOAD = "payload"  # CRC fine, payload does not fit its type
REJECT_TRUNCATED = "truncated"  # the stream ended (link lost) inside the frame
REJECT_REASONS = (REJECT_VERSION, REJECT_LENGTH, REJECT_CRC, REJECT_TYPE, REJECT_PAYLOAD, REJECT_TRUNCATED)


@dataclasses.dataclass(frozen=True)
class Frame:
    """A decoded frame: the sender's sequence number and timestamp, and its body."""

    sequence: int
    timestamp_ns: int
    body: Body


def encode_frame(frame: Frame) -> bytes:
    """The bytes of ``frame`` on the wire. ValueError if a field does not fit its width."""
    payload = frame.body.encode()
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise ValueError(f"payload of {len(payload)} bytes exceeds MAX_PAYLOAD_BYTES = {MAX_PAYLOAD_BYTES}")
    header = HEADER.pack(VERSION, frame.body.TYPE, len(payload), frame.sequence % SEQUENCE_MODULUS, frame.timestamp_ns)
    return SYNC + header + payload + CRC.pack(zlib.crc32(payload, zlib.crc32(header)))


class FrameDecoder:
    """Finds frames in a byte stream fed in pieces of any size.

    Invariants (tests/device/test_framing.py): ``feed`` never raises; every frame it returns was
    encoded exactly so; ``bytes_in == bytes of returned frames + discarded_bytes + pending``.
    After a rejection the decoder steps one byte past the rejected sync word and searches
    again, so a corrupted length never swallows the good frames that follow.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self.rejected: Counter = Counter()  # by REJECT_* reason
        self.discarded_bytes = 0  # bytes that were not part of a returned frame
        self.frames = 0  # frames returned

    @property
    def rejected_total(self) -> int:
        return sum(self.rejected.values())

    @property
    def pending_bytes(self) -> int:
        return len(self._buffer)

    def feed(self, data: bytes) -> list[Frame]:
        """The frames completed by ``data``, in stream order."""
        self._buffer += data
        frames = []
        while (frame := self._next()) is not None:
            frames.append(frame)
        return frames

    def finish(self) -> list[Frame]:
        """The stream has ended (the link was lost): a frame begun but not completed is
        counted as truncated and dropped; complete frames found behind it are returned."""
        frames = self.feed(b"")
        while self._buffer:
            if self._buffer.startswith(SYNC):
                self._reject(REJECT_TRUNCATED)
            else:
                self._discard(len(self._buffer))
            frames += self.feed(b"")
        return frames

    def _discard(self, n: int) -> None:
        del self._buffer[:n]
        self.discarded_bytes += n

    def _reject(self, reason: str) -> None:
        self.rejected[reason] += 1
        self._discard(1)

    def _next(self) -> Frame | None:
        """The next frame at the front of the buffer, or None when more bytes are needed."""
        while True:
            start = self._buffer.find(SYNC)
            if start < 0:
                # Keep a last byte that may be the first half of a sync word.
                self._discard(len(self._buffer) - (1 if self._buffer.endswith(SYNC[:1]) else 0))
                return None
            self._discard(start)
            if len(self._buffer) < HEADER_BYTES:
                return None
            version, kind, length, sequence, timestamp_ns = HEADER.unpack_from(self._buffer, len(SYNC))
            if version != VERSION:
                self._reject(REJECT_VERSION)
                continue
            if length > MAX_PAYLOAD_BYTES:
                self._reject(REJECT_LENGTH)
                continue
            end = HEADER_BYTES + length + CRC.size
            if len(self._buffer) < end:
                return None
            payload = bytes(self._buffer[HEADER_BYTES : HEADER_BYTES + length])
            (crc,) = CRC.unpack_from(self._buffer, HEADER_BYTES + length)
            if crc != zlib.crc32(self._buffer[len(SYNC) : HEADER_BYTES + length]):
                self._reject(REJECT_CRC)
                continue
            body_type = BODY_TYPES.get(kind)
            if body_type is None:
                self._reject(REJECT_TYPE)
                continue
            try:
                body = body_type.decode(payload)
            except PayloadError:
                self._reject(REJECT_PAYLOAD)
                continue
            del self._buffer[:end]
            self.frames += 1
            return Frame(sequence, timestamp_ns, body)
