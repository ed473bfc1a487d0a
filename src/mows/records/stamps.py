"""Stamps of the device clock in messages (REP-145: the time of the first sample).

A ``builtin_interfaces/Time`` (or anything with ``sec`` and ``nanosec``: rclpy messages and
rosbags' decoded ones alike) to and from integer nanoseconds or float seconds. The stream
works in integer nanoseconds (20 kS/s is exactly 50 000 ns a sample); float seconds are for
arithmetic on the samples, where 0.1 µs at today's epoch is far below a sample.
"""

from __future__ import annotations

import math

NS_PER_S = 1_000_000_000


def nanoseconds(stamp) -> int:
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def seconds(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def set_nanoseconds(stamp, stamp_ns: int) -> None:
    """Write integer nanoseconds into ``stamp`` (in place: header stamps are fields)."""
    stamp.sec, stamp.nanosec = divmod(int(stamp_ns), NS_PER_S)


def set_seconds(stamp, time_s: float) -> None:
    """Write float seconds into ``stamp``, rounded to the nanosecond."""
    if not math.isfinite(time_s):
        raise ValueError(f"stamp {time_s!r} s is not a time")
    set_nanoseconds(stamp, round(time_s * NS_PER_S))
