"""A test node spun on demand: tests wait for conditions, never for a fixed time. The ``start``
fixture (node_processes.py) runs node processes with their output logged, ``action_server`` a
node of the graph as an action server."""

import time
from collections.abc import Callable

import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor

# Only a bound for a test that hangs; a test passes as soon as its condition holds.
WAIT_S = float(__import__("os").environ.get("MOWS_TEST_WAIT_S", 60.0))


class RosHarness:
    def __init__(self):
        self.node = rclpy.create_node("mows_test")
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)

    def wait_for(self, condition: Callable[[], object], what: str, bound_s: float = WAIT_S):
        """Spin until ``condition()`` is true and return its value; fail after ``bound_s``."""
        deadline = time.monotonic() + bound_s
        while not (value := condition()):
            if time.monotonic() > deadline:
                raise AssertionError(f"gave up after {bound_s} s waiting for {what}")
            self.executor.spin_once(timeout_sec=0.1)
        return value

    def close(self):
        # Everything is destroyed in order, children first: the node leaves the executor, and
        # the action clients tests made (waitables, which destroy_node leaves alone) go before
        # the node. A worker crashed in destroy_node twice (a segfault, rclpy jazzy).
        self.executor.remove_node(self.node)
        for waitable in list(self.node.waitables):
            waitable.destroy()
        self.node.destroy_node()
        self.executor.shutdown()


@pytest.fixture
def ros(ros_context):
    harness = RosHarness()
    yield harness
    harness.close()


from node_processes import action_server, start  # noqa: E402,F401 (the fixtures, shared by the node tests)
