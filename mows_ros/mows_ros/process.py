"""Run one node as a process: spin until SIGINT or SIGTERM, then leave cleanly (exit 0).

    <node executable> [--autostart] [--ros-args ...]

A node starts unconfigured, for a supervisor (mows-graph, ``ros2 lifecycle``) to bring up;
``--autostart`` configures and activates it at once, as a node run alone needs.
"""

import argparse
import faulthandler
import re
import signal
import sys
import time
from collections.abc import Callable

import rclpy
from rclpy.exceptions import (
    InvalidParameterTypeException,
    InvalidParameterValueException,
    ParameterUninitializedException,
)
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from mows_ros.node import MowsNode
from mows_ros.params import UnknownParameterError, params_file_problem, ros_argument_values

EXIT_BAD_PARAMETER = 2
RCLInvalidROSArgsError = rclpy_implementation.RCLInvalidROSArgsError
AUTOSTART = "--autostart"
SHUTDOWN_WAIT_S = 5.0  # a bound only: a signal handler's thread shuts down in milliseconds
STOP_POLL_S = 0.1  # the executor's longest wait: how soon a stop signal is taken when nothing else wakes it


def arguments_problem(argv: list[str]) -> str | None:
    """Why the command line cannot start a node (rcl's refusal of the ROS arguments, in one
    line; a parameter file that is none), or None."""
    try:
        remove_ros_args(argv)
    except RCLInvalidROSArgsError as error:
        return _rcl_refusal(str(error))
    for path in ros_argument_values(argv, ("--params-file",)):
        if (problem := params_file_problem(path)) is not None:
            return problem
    return None


def _rcl_refusal(text: str) -> str:
    """rcl's refusal of a ROS argument in one line: the argument and the parser's reason, without
    rcl's source locations and trailing newline. For an override rule its reason is the lexer's
    state (or "error not set" for an empty value): the rule's form says more."""
    text = re.sub(r", at \S+:\d+", "", text).removeprefix("Failed to parse ROS arguments: ")
    text = " ".join(text.split())
    if "parameter override rule" in text:
        return text.partition(". Error: ")[0] + " (the form is -p [node:]name:=value; an empty string is '')"
    return text


def autostart_asked(args: list[str] | None) -> bool:
    """Whether the arguments outside of ``--ros-args`` ask for ``--autostart``."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument(AUTOSTART, action="store_true", help="configure and activate the node at start-up")
    return parser.parse_args(remove_ros_args(sys.argv if args is None else args)[1:]).autostart


def run_node(make_node: Callable[[], MowsNode], args: list[str] | None = None) -> int:
    """Create the node with ``make_node`` and spin it on one thread; return the exit code.

    A callback that waits (the driver's run_cycle, the estimator's calibration, the mapper's
    sweep) is a coroutine that awaits what other callbacks deliver; work of seconds of CPU
    runs in a worker thread it awaits (``mows_ros.awaitables.in_worker``). Not a
    MultiThreadedExecutor: rclpy 7.1.6's re-submits a callback its pool has not started yet
    without waiting, starves the pool of the GIL, and never shuts the pool down.

    SIGINT and SIGTERM ask the node to stop (:class:`StopSignals`, not rclpy's handlers): the
    executor stops spinning, the node releases what it holds while its context still runs (its
    last log lines reach /rosout, where after rclpy's handler each failed with "publisher's
    context is invalid"), and only then is the context shut down. A second signal stops it at
    once (KeyboardInterrupt). Either is the normal way for a node to stop. A value from a
    parameter file or ``-p`` that the node rejects, or a parameter it does not have, ends it
    with EXIT_BAD_PARAMETER and the reason, not a traceback: it is a configuration error, not
    a bug. So does a configure or activate refused with ``--autostart``.
    """
    faulthandler.enable()  # a node aborted because it would not stop says where it hung
    if (problem := arguments_problem(sys.argv if args is None else args)) is not None:
        sys.stderr.write(f"error: {problem}\n")
        return EXIT_BAD_PARAMETER
    autostart = autostart_asked(args)
    stop = StopSignals()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    node = None
    executor = SingleThreadedExecutor()
    try:
        node = make_node()
        if autostart and (problem := node.start_active()) is not None:
            sys.stderr.write(f"error: {problem}\n")
            return EXIT_BAD_PARAMETER
        executor.add_node(node)
        while not stop.asked:
            executor.spin_once(timeout_sec=STOP_POLL_S)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # A context shut down from under the executor (by another handler than ours): one
        # building its next wait set gets an RCLError, one taking a message a plain RuntimeError
        # from the binding (RCLError is one too). Either is the normal end, but only if shutdown
        # happened.
        if not _shut_down_within(SHUTDOWN_WAIT_S):
            raise
    except (InvalidParameterValueException, InvalidParameterTypeException, UnknownParameterError) as error:
        sys.stderr.write(f"error: {error}\n")
        return EXIT_BAD_PARAMETER
    except ParameterUninitializedException as error:  # an override of no type: [] or ~
        sys.stderr.write(f"error: {error}: give it a value (an empty list has no type in ROS)\n")
        return EXIT_BAD_PARAMETER
    finally:
        if node is not None:
            node.destroy_node()
        _shutdown()
    return 0


class StopSignals:
    """SIGINT and SIGTERM, from their arrival on: the first asks the node to stop (``asked``),
    a second stops it at once. Python runs the handler between the executor's turns, which
    :data:`STOP_POLL_S` bounds."""

    def __init__(self):
        self.asked = False
        for number in (signal.SIGINT, signal.SIGTERM):
            signal.signal(number, self._on_signal)

    def _on_signal(self, number, _frame) -> None:
        if self.asked:
            raise KeyboardInterrupt
        self.asked = True


def _shut_down_within(timeout_s: float) -> bool:
    """Whether the context is shut down, or is within ``timeout_s``: rclpy's signal handler shuts
    it down from a thread of its own, so a take can fail before ``rclpy.ok()`` turns false (the viz
    node exited 1 on SIGTERM that way, under load)."""
    deadline = time.monotonic() + timeout_s
    while rclpy.ok():
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.01)
    return True


def _shutdown() -> None:
    """Shut the context down unless the signal handler has: try_shutdown checks, then shuts down,
    and a SIGINT between the two made the mapper exit 1 at the end of a demo (RCLError: rcl_shutdown
    already called)."""
    try:
        rclpy.try_shutdown()
    except RuntimeError:
        if rclpy.ok():
            raise
