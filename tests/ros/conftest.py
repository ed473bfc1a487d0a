"""A test node spun on demand: tests wait for conditions, never for a fixed time. The ``start``
fixture (node_processes.py) runs node processes with their output logged, ``action_server`` a
node of the graph as an action server. A failed test's report shows the logs of the processes
it started: the nodes' side of the failure."""

import subprocess
import sys
from pathlib import Path
from typing import NamedTuple

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


class DemoSession(NamedTuple):
    lines: list[str]  # what the demo printed
    out: Path  # its --out directory
    bag: Path  # its --record


@pytest.fixture(scope="session")
def demo_session(tmp_path_factory) -> DemoSession:
    """`make demo` (``mows-demo``) once for the tests that read what it prints or records, all
    in the "realtime" group, so on one worker: a shorter sweep (6 orientations × 1 ring-down)
    that prints the same lines, the viz node on any free port (``--foxglove=0``), and the
    session recorded by the driver (``--record``)."""
    out = tmp_path_factory.mktemp("demo")
    bag = out / "session"
    command = ["--angles", "6", "--repeats", "1", "--foxglove=0", "--out", str(out), "--record", str(bag)]
    run = subprocess.run(
        [sys.executable, "-m", "mows_bringup.demo", *command], capture_output=True, text=True, timeout=480
    )
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return DemoSession((run.stdout + run.stderr).splitlines(), out, bag)
