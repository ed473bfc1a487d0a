"""A test node spun on demand: tests wait for conditions, never for a fixed time. The ``start``
fixture (node_processes.py) runs node processes with their output logged, ``action_server`` a
node of the graph as an action server."""

import pytest

from node_processes import RosHarness, action_server, start  # noqa: F401 (the fixtures, shared by the node tests)


@pytest.fixture
def ros(ros_context):
    harness = RosHarness()
    yield harness
    harness.close()
