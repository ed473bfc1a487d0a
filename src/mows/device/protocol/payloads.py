"""The payloads of the serial link's frame types (docs/serial_protocol.md): one ``Body`` class
per type, with its TYPE code, its fields and its exact wire layout (little-endian, encode and a
decode that checks the bytes fit), and ``BODY_TYPES``, the table the frame decoder
(``mows.device.protocol.framing``) picks a type's class from.
"""

from __future__ import annotations

import dataclasses
import math
import struct
from typing import ClassVar, Self

import numpy as np


class PayloadError(ValueError):
    """A payload that does not fit its frame type."""


class Body:
    """A frame's payload. Subclasses define TYPE, ``encode() -> bytes`` and ``decode(bytes)``
    (PayloadError when the bytes do not fit)."""

    TYPE: ClassVar[int]

    def encode(self) -> bytes:
        raise NotImplementedError

    @classmethod
    def decode(cls, payload: bytes) -> Body:
        raise NotImplementedError


def _unpack_exact(layout: struct.Struct, payload: bytes, what: str) -> tuple:
    if len(payload) != layout.size:
        raise PayloadError(f"{what} payload has {len(payload)} bytes, expected {layout.size}")
    return layout.unpack(payload)


class FixedBody(Body):
    """A payload of fixed size: the dataclass fields, in order, packed with LAYOUT."""

    LAYOUT: ClassVar[struct.Struct]

    def encode(self) -> bytes:
        return self.LAYOUT.pack(*dataclasses.astuple(self))  # type: ignore[call-overload]  # subclasses are dataclasses

    @classmethod
    def decode(cls, payload: bytes) -> Self:
        return cls(*_unpack_exact(cls.LAYOUT, payload, cls.__name__))


# --- device → host --------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class DeviceInfo(FixedBody):
    """What the device is: sent after boot, after a reconnection and in reply to Hello."""

    TYPE: ClassVar[int] = 0x01
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<dBBdddd")
    sample_rate_hz: float
    n_channels: int
    n_coils: int
    range_t: float  # full scale of every channel, ±range_t
    resolution_t: float  # one count of a Samples frame, tesla
    current_cap_a: float  # the device refuses coil amplitudes above this
    watchdog_timeout_s: float  # coils off when no host frame arrived for this long

    @classmethod
    def decode(cls, payload: bytes) -> Self:
        info = super().decode(payload)
        for name in ("sample_rate_hz", "range_t", "resolution_t"):
            value = getattr(info, name)
            if not (math.isfinite(value) and value > 0):
                raise PayloadError(f"DeviceInfo {name} = {value!r}, expected a positive number")
        if info.n_channels == 0:
            raise PayloadError("DeviceInfo reports no channels")
        return info


@dataclasses.dataclass(frozen=True, eq=False)
class Samples(Body):
    """Consecutive samples of every channel: sample i was taken at the frame's timestamp +
    i / sample_rate_hz. ``counts`` (n, channels) int32 in units of DeviceInfo.resolution_t,
    ``saturated`` (n, channels) bool; both sample-major on the wire, the flags packed 8 to a
    byte, first flag in the most significant bit, unused bits zero."""

    TYPE: ClassVar[int] = 0x02
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<QHB")
    first_sample_index: int
    counts: np.ndarray
    saturated: np.ndarray

    def encode(self) -> bytes:
        n, channels = self.counts.shape
        return (
            self.LAYOUT.pack(self.first_sample_index, n, channels)
            + self.counts.astype("<i4", copy=False).tobytes()
            + np.packbits(self.saturated.astype(bool, copy=False)).tobytes()
        )

    @classmethod
    def decode(cls, payload: bytes) -> Samples:
        if len(payload) < cls.LAYOUT.size:
            raise PayloadError(f"Samples payload of {len(payload)} bytes is shorter than its header")
        first, n, channels = cls.LAYOUT.unpack_from(payload)
        values = n * channels
        flag_bytes = math.ceil(values / 8)
        expected = cls.LAYOUT.size + 4 * values + flag_bytes
        if n == 0 or channels == 0 or len(payload) != expected:
            raise PayloadError(
                f"Samples payload of {len(payload)} bytes does not hold {n} samples × "
                f"{channels} channels ({expected} bytes)"
            )
        counts = np.frombuffer(payload, "<i4", values, cls.LAYOUT.size).reshape(n, channels)
        packed = np.frombuffer(payload, np.uint8, flag_bytes, cls.LAYOUT.size + 4 * values)
        flags = np.unpackbits(packed)
        if flags[values:].any():
            raise PayloadError("Samples payload has saturation bits set beyond its last sample")
        return cls(first, counts.astype(np.int32), flags[:values].astype(bool).reshape(n, channels))

    def __eq__(self, other) -> bool:
        return (
            isinstance(other, Samples)
            and self.first_sample_index == other.first_sample_index
            and np.array_equal(self.counts, other.counts)
            and np.array_equal(self.saturated, other.saturated)
        )


@dataclasses.dataclass(frozen=True)
class Ack(FixedBody):
    """The device's answer to a host command (Coils, Orientation, FieldCurrent): accepted or why
    not, and the device sample index from which the command takes (or took) effect (for
    FieldCurrent: the sample at which the supply's ramp reaches the current)."""

    TYPE: ClassVar[int] = 0x03
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<IBQ")
    OK: ClassVar[int] = 0
    REFUSED_OVER_CAP: ClassVar[int] = 1  # a coil amplitude above DeviceInfo.current_cap_a, or a
    # supply current above the supply's cap
    REFUSED_INVALID: ClassVar[int] = 2  # wrong coil count, non-finite value, frequency out of
    # range, no supply
    REFUSED_BUSY: ClassVar[int] = 3  # orientation change while the coils are on
    REASONS: ClassVar[dict] = {
        0: "accepted",
        1: "current above the device's cap",
        2: "invalid command",
        3: "coils are on",
    }
    command_sequence: int  # the sequence number of the host frame answered
    result: int
    applied_sample_index: int  # meaningful when result is OK

    @property
    def accepted(self) -> bool:
        return self.result == self.OK

    @property
    def reason(self) -> str:
        return self.REASONS.get(self.result, f"unknown result code {self.result}")


@dataclasses.dataclass(frozen=True)
class Status(FixedBody):
    """The device's heartbeat, every 100 ms, and at once when its watchdog trips: its sample
    counter, coil state and own counters."""

    TYPE: ClassVar[int] = 0x04
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<QBIII")
    next_sample_index: int  # the next sample the device will take
    coils_on: bool
    watchdog_trips: int  # times the heartbeat watchdog switched the coils off
    dropped_frames: int  # frames the device could not send (host not reading)
    rejected_frames: int  # host frames the device's decoder rejected

    @classmethod
    def decode(cls, payload: bytes) -> Self:
        status = super().decode(payload)
        if status.coils_on not in (0, 1):
            raise PayloadError(f"Status coils_on byte is {status.coils_on}, expected 0 or 1")
        return dataclasses.replace(status, coils_on=bool(status.coils_on))


# --- host → device --------------------------------------------------------------------------
class EmptyBody(Body):
    """A body without payload: the frame type says it all."""

    def encode(self) -> bytes:
        return b""

    @classmethod
    def decode(cls, payload: bytes) -> EmptyBody:
        if payload:
            raise PayloadError(f"{cls.__name__} payload has {len(payload)} bytes, expected none")
        return cls()

    def __eq__(self, other) -> bool:
        return type(other) is type(self)


class Hello(EmptyBody):
    """Asks the device for its DeviceInfo (sent by the host after it opens the port)."""

    TYPE: ClassVar[int] = 0x10


class Heartbeat(EmptyBody):
    """The host is alive. The device switches the coils off when no host frame has arrived
    for DeviceInfo.watchdog_timeout_s."""

    TYPE: ClassVar[int] = 0x11


@dataclasses.dataclass(frozen=True)
class Coils(Body):
    """Drive coil k with amplitudes_a[k]·sin(2πf·(t − t_on)) from device sample
    ``at_sample_index`` on (t_on = that sample); all amplitudes 0 switches the coils off.

    A command for a sample already taken applies at the next one. IMMEDIATE applies at the
    next sample and cancels every command scheduled before (the emergency stop)."""

    TYPE: ClassVar[int] = 0x12
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<BQdB")
    IMMEDIATE: ClassVar[int] = 0x01
    flags: int
    at_sample_index: int
    frequency_hz: float
    amplitudes_a: tuple

    def encode(self) -> bytes:
        count = len(self.amplitudes_a)
        return self.LAYOUT.pack(self.flags, self.at_sample_index, self.frequency_hz, count) + struct.pack(
            f"<{count}d", *self.amplitudes_a
        )

    @classmethod
    def decode(cls, payload: bytes) -> Coils:
        if len(payload) < cls.LAYOUT.size:
            raise PayloadError(f"Coils payload of {len(payload)} bytes is shorter than its header")
        flags, at_index, frequency, count = cls.LAYOUT.unpack_from(payload)
        amplitudes = _unpack_exact(struct.Struct(f"<{count}d"), payload[cls.LAYOUT.size :], "Coils amplitudes")
        if flags & ~cls.IMMEDIATE:
            raise PayloadError(f"Coils flags 0x{flags:02x} has unknown bits")
        return cls(flags, at_index, frequency, amplitudes)

    @property
    def immediate(self) -> bool:
        return bool(self.flags & self.IMMEDIATE)


@dataclasses.dataclass(frozen=True)
class Orientation(FixedBody):
    """Turn the probe (the rotation stage) to theta0_rad from sample ``at_sample_index`` on."""

    TYPE: ClassVar[int] = 0x13
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<Qd")
    at_sample_index: int
    theta0_rad: float


@dataclasses.dataclass(frozen=True)
class FieldCurrent(FixedBody):
    """Ramp the static-field supply to ``current_a`` from sample ``at_sample_index`` on, within
    its slew limit (the device rounds to its resolution and refuses currents above its cap).
    TO_ZERO_NOW drops any ramp that waits and ramps to zero from the next sample (``current_a``
    must be 0): the host's cancel, and what the device's watchdog does by itself."""

    TYPE: ClassVar[int] = 0x14
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<BQd")
    TO_ZERO_NOW: ClassVar[int] = 0x01
    flags: int
    at_sample_index: int
    current_a: float

    @classmethod
    def decode(cls, payload: bytes) -> FieldCurrent:
        body = super().decode(payload)
        if body.flags & ~cls.TO_ZERO_NOW:
            raise PayloadError(f"FieldCurrent flags 0x{body.flags:02x} has unknown bits")
        if body.to_zero_now and body.current_a != 0.0:
            raise PayloadError(f"FieldCurrent TO_ZERO_NOW with current_a = {body.current_a!r}, expected 0")
        return body

    @property
    def to_zero_now(self) -> bool:
        return bool(self.flags & self.TO_ZERO_NOW)


BODY_TYPES: dict[int, type[Body]] = {
    cls.TYPE: cls for cls in (DeviceInfo, Samples, Ack, Status, Hello, Heartbeat, Coils, Orientation, FieldCurrent)
}
