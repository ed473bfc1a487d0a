"""Run one node as a process: spin until SIGINT or SIGTERM, then leave cleanly (exit 0)."""
import faulthandler
import sys
from collections.abc import Callable

import rclpy
from rclpy.exceptions import InvalidParameterTypeException, InvalidParameterValueException
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node

EXIT_BAD_PARAMETER = 2


def run_node(make_node: Callable[[], Node], args: list[str] | None = None, threads: int = 1) -> int:
    """Create the node with ``make_node`` and spin it; return the process exit code.

    ``threads`` > 1 spins a MultiThreadedExecutor, for a node whose callbacks run long enough
    to hold up the others (the mapper's sweep runs the lab). A callback that only waits for
    data other callbacks deliver is better a coroutine on one thread (the driver's run_cycle,
    the estimator's calibration): rclpy 7.1.6's MultiThreadedExecutor re-submits a callback
    its pool has not started yet without waiting, and starves the pool of the GIL.

    ``rclpy.init`` installs handlers for SIGINT and SIGTERM that shut the context down, so
    either signal ends ``spin`` with ``ExternalShutdownException`` (or KeyboardInterrupt when
    it lands outside of spin): both are the normal way for a node to stop. A value from a
    parameter file or ``-p`` that the node rejects ends it with EXIT_BAD_PARAMETER and the
    reason, not a traceback: it is a configuration error, not a bug.
    """
    faulthandler.enable()  # a node aborted because it would not stop says where it hung
    rclpy.init(args=args)
    node = None
    executor = MultiThreadedExecutor(num_threads=threads) if threads > 1 else SingleThreadedExecutor()
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
    except (InvalidParameterValueException, InvalidParameterTypeException) as error:
        sys.stderr.write(f"error: {error}\n")
        return EXIT_BAD_PARAMETER
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
        if isinstance(executor, MultiThreadedExecutor):
            # rclpy 7.1.6 never shuts its worker pool down (later releases do, in shutdown()),
            # and an idle worker once held the interpreter's exit for good.
            executor._executor.shutdown(wait=False, cancel_futures=True)
    return 0
