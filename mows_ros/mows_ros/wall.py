"""Timers and stamps on the host's own clocks, whatever ``use_sim_time`` says.

A node started with ``use_sim_time:=true`` runs its ROS clock from ``/clock``; with no
simulator publishing it, that clock stands at zero and a timer on it never fires. What MOWS
times is real: a device streams in real time, a client waits in real time, and a supervisor
reads /diagnostics in real time. So its timers run on the steady clock (/diagnostics is
stamped on ROS time once ``/clock`` runs it, ``mows_ros.diagnostics``); the data keep the
device's stamps (REP-145) either way.
"""

from collections.abc import Callable

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.timer import Timer

STEADY = Clock(clock_type=ClockType.STEADY_TIME)
SYSTEM = Clock(clock_type=ClockType.SYSTEM_TIME)


def steady_timer(node: Node, period_s: float, callback: Callable[[], object], **kwargs) -> Timer:
    """``node.create_timer`` on the steady clock: it fires under simulated time too."""
    return node.create_timer(period_s, callback, clock=STEADY, **kwargs)


def wall_stamp():
    """Now on the system clock, as a ``builtin_interfaces/Time``."""
    return SYSTEM.now().to_msg()
