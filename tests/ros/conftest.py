"""A test node spun on demand: tests wait for conditions, never for a fixed time. The ``start``
fixture (node_processes.py) runs node processes with their output logged, ``action_server`` a
node of the graph as an action server. A failed test's report shows the logs of the processes
it started: the nodes' side of the failure."""

import re
import subprocess
import sys
import threading
from pathlib import Path
from typing import NamedTuple

import pytest

from foxglove_client import FoxgloveClient
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
    live: FoxgloveClient  # a viewer connected from the address it printed until the end


DEMO_BOUND_S = 480.0
FOXGLOVE_ADDRESS = re.compile(r"Foxglove: open ws://127\.0\.0\.1:(\d+)")


@pytest.fixture(scope="session")
def demo_session(tmp_path_factory) -> DemoSession:
    """`make demo` (``mows-demo``) once for the tests that read what it prints or records, all
    in the "realtime" group, so on one worker: a shorter sweep (6 orientations × 1 ring-down)
    that prints the same lines, the viz node on any free port (``--foxglove=0``) with a viewer
    connected as soon as the demo prints its address, and the session recorded by the driver
    (``--record``)."""
    out = tmp_path_factory.mktemp("demo")
    bag = out / "session"
    command = ["--angles", "6", "--repeats", "1", "--foxglove=0", "--out", str(out), "--record", str(bag)]
    with open(out / "demo.stderr", "w+") as stderr:
        demo = subprocess.Popen(
            [sys.executable, "-m", "mows_bringup.demo", *command], stdout=subprocess.PIPE, stderr=stderr, text=True
        )
        bound = threading.Timer(DEMO_BOUND_S, demo.kill)
        bound.start()
        lines, live = [], None
        for line in demo.stdout:
            lines.append(line.rstrip("\n"))
            if live is None and (found := FOXGLOVE_ADDRESS.search(line)) is not None:
                live = FoxgloveClient(int(found.group(1)))
        demo.wait()
        bound.cancel()
        stderr.seek(0)
        lines += stderr.read().splitlines()
    assert demo.returncode == 0, "\n".join(lines[-60:])
    assert live is not None, "\n".join(lines)
    live.ended.wait(60)  # the viz node stopped: what it sent is here
    live.close()
    return DemoSession(lines, out, bag, live)
