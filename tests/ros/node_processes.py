"""Node processes for tests: started with their output in a log file, killed if a test leaves
them behind; and a node of the graph started as an action server, with its goals sent."""

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable

import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.action import MeasurementCycle
from mows_msgs.msg import RingdownFit
from rclpy.action import ActionClient, ActionServer, CancelResponse
from rclpy.executors import SingleThreadedExecutor
from rclpy.task import Future

from mows_bringup.nodes import NODES
from mows_ros.qos import RESULT_QOS

# Only a bound for a test that hangs; a test passes as soon as its condition holds.
WAIT_S = float(os.environ.get("MOWS_TEST_WAIT_S", 60.0))
# The bound for a node process to come up, to be discovered and to report (or to die): its
# imports, kernels and DDS discovery take minutes at a load of 35 on two cores.
START_S = 300.0


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

    def diagnostics_of(self, name: str) -> dict[str, str]:
        """The key-values the node ``name`` reports on /diagnostics, each as last reported,
        kept up to date as this node spins (empty until its first report)."""
        values: dict[str, str] = {}

        def take(array: DiagnosticArray) -> None:
            values.update({kv.key: kv.value for s in array.status if s.name == name for kv in s.values})

        self.node.create_subscription(DiagnosticArray, "/diagnostics", take, 10)
        return values

    def wait_for_estimator_hearing(self, name: str = "/estimator") -> None:
        """Wait until the estimator ``name`` reports blocks heard on /diagnostics, as a supervisor
        would before a first cycle: discovery takes seconds on a loaded machine, and a ring-down
        over before the estimator's first block is counted by it, not fitted."""
        heard: list[int] = []

        def on_diagnostics(array: DiagnosticArray) -> None:
            heard.extend(int(kv.value) for s in array.status if s.name == name for kv in s.values if kv.key == "blocks")

        subscription = self.node.create_subscription(DiagnosticArray, "/diagnostics", on_diagnostics, 10)
        try:
            self.wait_for(lambda: any(heard), f"{name} hearing the stream", 300.0)
        finally:
            self.node.destroy_subscription(subscription)

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
def start(tmp_path, request):
    """Starts a command with its output in a log file; kills what is left at the end. A failed
    test's report carries every log (``pytest_runtest_makereport`` in conftest.py).

    The command is killed with the test's worker too (setpriv --pdeathsig): a worker that
    crashed once left its nodes running in its ROS domain, which the replacement worker took
    over, and the suite hung on them."""
    processes = request.node.started_processes = []

    def start(*command: str, stdin=subprocess.DEVNULL) -> subprocess.Popen:
        processes.append(launch(command, tmp_path / f"process-{len(processes)}.log", stdin))
        return processes[-1]

    yield start
    for process in processes:
        if process.poll() is None:
            process.kill()
            process.wait()


def launch(command, log_path, stdin=subprocess.DEVNULL) -> subprocess.Popen:
    """``command`` with its output in ``log_path`` (``stdin``: subprocess.PIPE to type into
    it), killed with the test's worker.

    Its SIGINT is the default, as for a command run from a terminal: a suite started as a
    shell's background job inherits SIGINT ignored, and a Ctrl-C sent to the command would
    then be lost (GNU env's --default-signal)."""
    with open(log_path, "w") as log:
        process = subprocess.Popen(
            ["setpriv", "--pdeathsig", "KILL", "env", "--default-signal=INT", *command],
            stdin=stdin,
            stdout=log,
            stderr=subprocess.STDOUT,
        )
    process.log_path = log_path
    return process


def log(process: subprocess.Popen) -> str:
    return process.log_path.read_text()


@pytest.fixture
def action_server(ros, start):
    """Starts the graph's node ``name`` with ``-p`` parameters and returns (a client of its
    action once the server is ready, the process); at the end the node must exit cleanly."""
    started = []

    def action_server(name: str, action_type, action: str, *parameters: str):
        node = next(n for n in NODES if n.name == name)
        process = start(*node.command([arg for parameter in parameters for arg in ("-p", parameter)]))
        started.append(process)
        client = ActionClient(ros.node, action_type, action)
        ros.wait_for(
            lambda: client.server_is_ready() or process.poll() is not None, f"the {action} action server", START_S
        )
        assert process.poll() is None, log(process)
        return client, process

    yield action_server
    for process in started:
        assert_stops_cleanly(process)


def assert_stops_cleanly(process: subprocess.Popen) -> None:
    """SIGTERM; the node must exit 0 within 30 s (killed after that, never left behind to
    talk to the next test)."""
    process.terminate()
    try:
        code = process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        code = process.wait()
    assert code == 0, log(process)


# A goal is answered in milliseconds. Rarely (about once in six full suites) a goal sent as soon
# as the server is ready (the client has discovered it) is never answered, not even refused, and
# the mapper logs no goal: the request or its answer is lost between the two participants. Such
# a goal is sent again, as a new goal, a bounded number of times.
GOAL_ANSWER_S = 15.0
GOAL_SENDS = 3


def send_goal(ros, client, goal, cancel_after_feedback=None, result_bound_s=WAIT_S):
    """Sends ``goal``: (its handle, its result or None if refused, the feedback that came), the
    goal cancelled after ``cancel_after_feedback`` feedback messages if that is given; the
    result awaited for at most ``result_bound_s``."""
    feedback = []
    handle = goal_answer(ros, client, goal, feedback.append)
    if not handle.accepted:
        return handle, None, feedback
    if cancel_after_feedback is not None:
        ros.wait_for(lambda: len(feedback) >= cancel_after_feedback, "feedback")
        handle.cancel_goal_async()
    result = handle.get_result_async()
    done = ros.wait_for(lambda: result.done() and result.result(), "the goal's result", result_bound_s)
    return handle, done, feedback


def goal_answer(ros, client, goal, on_feedback=None):
    """The handle of ``goal`` once the server answered it (accepted or not), sent again as a new
    goal if no answer came (``GOAL_ANSWER_S``, ``GOAL_SENDS``); ``on_feedback`` takes each
    feedback message of the goal."""
    sends = 1
    while True:
        sent = client.send_goal_async(
            goal, feedback_callback=None if on_feedback is None else lambda f: on_feedback(f.feedback)
        )
        try:
            return ros.wait_for(lambda sent=sent: sent.done() and sent.result(), "the goal's answer", GOAL_ANSWER_S)
        except AssertionError:
            if sends == GOAL_SENDS:
                raise
            print(f"goal not answered in {GOAL_ANSWER_S} s (send {sends} of {GOAL_SENDS}): sending it again")
            sends += 1


def serve_cycles(ros, run_cycle) -> ActionServer:
    """A stand-in for the driver's measurement-cycle action on the test node: each goal is
    answered by ``run_cycle(goal, result)`` (RunCycle's fields, as the driver's service has)."""

    def execute(goal_handle):
        result = run_cycle(goal_handle.request, MeasurementCycle.Result())
        goal_handle.succeed() if result.success else goal_handle.abort()
        return result

    return ActionServer(ros.node, MeasurementCycle, "driver/measurement_cycle", execute)


def leave_while_running(ros, start, driver, action_type: str, action: str, goal: str) -> None:
    """A client of ``action`` in a process of its own (:func:`goal_client`) sends ``goal``;
    once its goal runs a cycle of ``driver`` (:class:`HeldCycles`) and it heard the goal
    accepted (which may come after), Ctrl-C: returns once the node cancelled that cycle."""
    client = start(sys.executable, "-c", goal_client(action_type, action, goal))
    ros.wait_for(lambda: driver.goals, "the goal's first cycle")
    ros.wait_for(lambda: "accepted" in log(client), "the client to hear its goal accepted")
    client.send_signal(signal.SIGINT)
    assert client.wait(timeout=30) == 0, log(client)
    ros.wait_for(lambda: driver.cancelled, "the node to cancel the cycle nobody waits for")


def goal_client(action_type: str, action: str, goal: str) -> str:
    """A program that sends ``goal`` (Python, of the mows_msgs action ``action_type``) to
    ``action`` and waits for its result until it is stopped (Ctrl-C), as ``ros2 action
    send_goal`` does; it prints "accepted" once the goal is."""
    return f"""
import rclpy
from rclpy.action import ActionClient
from rclpy.executors import ExternalShutdownException
from mows_msgs.action import {action_type}
rclpy.init()
node = rclpy.create_node("goal_requester")
client = ActionClient(node, {action_type}, "{action}")
client.wait_for_server()
sent = client.send_goal_async({goal})
try:
    rclpy.spin_until_future_complete(node, sent)
    print("accepted", flush=True)
    rclpy.spin_until_future_complete(node, sent.result().get_result_async())
except (KeyboardInterrupt, ExternalShutdownException):
    pass
node.destroy_node()
rclpy.try_shutdown()
"""


class HeldCycles:
    """A stand-in driver whose measurement cycles run until they are cancelled."""

    def __init__(self, ros):
        self.goals, self.cancelled = [], []
        self.fits = ros.node.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)  # a node waits for one
        self.server = ActionServer(
            ros.node,
            MeasurementCycle,
            "driver/measurement_cycle",
            self.execute,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
        )
        self._ros = ros

    async def execute(self, goal_handle):
        self.goals.append(goal_handle)
        ended = Future()
        timer = self._ros.node.create_timer(
            0.05, lambda: goal_handle.is_cancel_requested and not ended.done() and ended.set_result(True)
        )
        await ended
        self._ros.node.destroy_timer(timer)
        self.cancelled.append(goal_handle)
        goal_handle.canceled()
        return MeasurementCycle.Result(success=False, message="cancelled: its goal was cancelled")
