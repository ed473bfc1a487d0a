"""A test node spun on demand: tests wait for conditions, never for a fixed time. The ``start``
fixture (node_processes.py) runs node processes with their output logged, ``action_server`` a
node of the graph as an action server. A failed test's report shows the logs of the processes
it started: the nodes' side of the failure."""

import pytest

from node_processes import RosHarness, action_server, log, start  # noqa: F401 (the fixtures, shared by the node tests)


@pytest.fixture
def ros(ros_context):
    harness = RosHarness()
    yield harness
    harness.close()


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    outcome = yield
    report = outcome.get_result()
    if report.failed and call.when == "call":
        for k, process in enumerate(getattr(item, "started_processes", [])):
            report.sections.append((f"process {k}: {' '.join(process.args[5:])}", log(process)[-20_000:]))
