"""Run one node as a process: spin until SIGINT or SIGTERM, then leave cleanly (exit 0)."""

import faulthandler
import sys
from collections.abc import Callable

import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node

from mows_ros.params import UnknownParameterError

EXIT_BAD_PARAMETER = 2


def run_node(make_node: Callable[[], Node], args: list[str] | None = None) -> int:
    """Create the node with ``make_node`` and spin it on one thread; return the exit code.

    A callback that waits (the driver's run_cycle, the estimator's calibration, the mapper's
    sweep) is a coroutine that awaits what other callbacks deliver; work of seconds of CPU
    runs in a worker thread it awaits (``mows_ros.awaitables.in_worker``). Not a
    MultiThreadedExecutor: rclpy 7.1.6's re-submits a callback its pool has not started yet
    without waiting, starves the pool of the GIL, and never shuts the pool down.

    ``rclpy.init`` installs handlers for SIGINT and SIGTERM that shut the context down, so
    either signal ends ``spin`` with ``ExternalShutdownException`` (or KeyboardInterrupt when
    it lands outside of spin): both are the normal way for a node to stop. A value from a
    parameter file or ``-p`` that the node rejects, or a parameter it does not have, ends it
    with EXIT_BAD_PARAMETER and the reason, not a traceback: it is a configuration error, not
    a bug.
    """
    faulthandler.enable()  # a node aborted because it would not stop says where it hung
    rclpy.init(args=args)
    node = None
    executor = SingleThreadedExecutor()
    try:
        node = make_node()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # The signal handler shuts the context down from under the executor: one building its
        # next wait set gets an RCLError, one taking a message a plain RuntimeError from the
        # binding (RCLError is one too). Either is the normal end, but only if shutdown happened.
        if rclpy.ok():
            raise
    except (InvalidParameterValueException, InvalidParameterTypeException, UnknownParameterError) as error:
        sys.stderr.write(f"error: {error}\n")
        return EXIT_BAD_PARAMETER
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
