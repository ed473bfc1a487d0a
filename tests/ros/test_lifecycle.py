"""Managed nodes: the driver taken through every lifecycle transition by the lifecycle_msgs
services, with the coil state and the topics it publishes checked in each state (a coil is
energised only while active); the error path releasing the device; mows-graph bringing the
graph up in order, or leaving it unconfigured for a supervisor."""

import re
import time

import pytest
from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from lifecycle_msgs.msg import Transition
from mows_msgs.action import RotationSweep
from mows_msgs.msg import ExcitationState, MagnetometerBlock, RingdownFit
from mows_msgs.srv import CalibrateF00, EmergencyStop, RunCycle
from rclpy.action import ActionClient
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

from mows.device.cycle.phases import CycleRequest, Phase
from mows.records import stamps
from mows_bringup.lifecycle import BOUND_S, LifecycleClient
from mows_bringup.nodes import NODES
from mows_driver import node as driver
from mows_ros.qos import EXCITATION_QOS
from node_processes import WAIT_S, log, send_goal

pytestmark = pytest.mark.ros

RATE_HZ = 20_000.0
BLOCK = 500  # samples of a 25 ms block
SECOND = round(RATE_HZ)  # a second of device samples: how long a stopped stream is watched
RAW_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
QUICK_CYCLES = ["-p", "excite_s:=0.6", "-p", "ringdown_s:=0.3", "-p", "turn_settle_s:=0.1"]
NOT_ACTIVE = "the driver is not active"
GOALS = {  # the state each transition leads to
    Transition.TRANSITION_CONFIGURE: "inactive",
    Transition.TRANSITION_ACTIVATE: "active",
    Transition.TRANSITION_DEACTIVATE: "inactive",
    Transition.TRANSITION_CLEANUP: "unconfigured",
    Transition.TRANSITION_INACTIVE_SHUTDOWN: "finalized",
}


@pytest.fixture
def lifecycle():
    """A client of the nodes' lifecycle_msgs services (what mows-graph uses)."""
    client = LifecycleClient([], give_up=lambda: None)
    yield client
    client.close()


class Supervisor:
    """The test as a lifecycle supervisor of the driver, and what it hears of it."""

    def __init__(self, ros, lifecycle: LifecycleClient):
        self.ros = ros
        self.lifecycle = lifecycle
        node = ros.node
        self.blocks: list[MagnetometerBlock] = []
        self.joints: list[JointState] = []
        self.states: list[ExcitationState] = []
        self.reports: list[dict] = []  # every /driver status on /diagnostics, as key values
        node.create_subscription(MagnetometerBlock, "/mows/raw", self.blocks.append, RAW_QOS)
        node.create_subscription(JointState, "/mows/joint_states", self.joints.append, 10)
        node.create_subscription(ExcitationState, "/mows/excitation", self.states.append, EXCITATION_QOS)
        node.create_subscription(DiagnosticArray, "/diagnostics", self._diagnostics, 10)
        self.run_cycle = node.create_client(RunCycle, "/mows/driver/run_cycle")
        self.estop = node.create_client(EmergencyStop, "/mows/driver/emergency_stop")

    def _diagnostics(self, array: DiagnosticArray) -> None:
        for status in array.status:
            if status.name == "/driver":
                self.reports.append({"message": status.message, **{kv.key: kv.value for kv in status.values}})

    def call(self, client, request):
        self.ros.wait_for(client.service_is_ready, f"the service {client.srv_name}")
        return client.call_async(request)

    def result(self, future):
        return self.ros.wait_for(lambda: future.done() and future.result(), "the service's response")

    def transition(self, transition_id: int) -> bool:
        """Through /driver/change_state (and /driver/get_state)."""
        return self.lifecycle.transition("driver", transition_id, GOALS[transition_id])

    def state(self) -> str:
        return self.lifecycle.state("driver")

    def report_in(self, state: str) -> dict:
        """The first report after this moment that gives ``state``."""
        seen = len(self.reports)
        return self.ros.wait_for(
            lambda: next((r for r in self.reports[seen:] if r["lifecycle_state"] == state), None),
            f"diagnostics in {state}",
        )

    def cycle(self, **request):
        return self.call(self.run_cycle, RunCycle.Request(**{"repeats": 1, "tuning_steps": 0, "gap_s": 0.0, **request}))

    def sample_index_of(self, state: ExcitationState) -> int:
        """The device sample of a phase, from its stamp and the blocks' clock."""
        block = self.blocks[0]
        epoch_ns = stamps.nanoseconds(block.header.stamp) - round(block.first_sample_index * 1e9 / RATE_HZ)
        return round((stamps.nanoseconds(state.header.stamp) - epoch_ns) * RATE_HZ / 1e9)

    def samples_read(self) -> int:
        return int(self.reports[-1].get("samples", 0)) if self.reports else 0

    def assert_silent_for_a_second(self, since_index: int) -> None:
        """The device goes on (its samples are read) while no block after ``since_index`` is
        published: waited for on the device's own sample count, not a timer."""
        self.ros.wait_for(lambda: self.samples_read() > since_index + SECOND, "a second of device samples")
        late = [b.first_sample_index for b in self.blocks if b.first_sample_index >= since_index]
        assert not late, f"blocks published while not active, from sample {late[0]}"


@pytest.fixture
def supervisor(ros, lifecycle):
    return Supervisor(ros, lifecycle)


def test_the_driver_energises_coils_only_while_active_through_every_transition(supervisor, start):
    sup = supervisor
    process = start(*NODES[0].command(QUICK_CYCLES, autostart=False))
    # unconfigured: no device link, no stream, cycles refused
    assert sup.state() == "unconfigured"
    report = sup.report_in("unconfigured")
    assert "unconfigured" in report["message"] and "samples" not in report
    refused = sup.result(sup.cycle(theta0_rad=0.0))
    assert not refused.success and "unconfigured" in refused.message
    stop = sup.result(sup.call(sup.estop, EmergencyStop.Request(engage=True, reason="test")))
    assert not stop.success and not stop.latched and "unconfigured: no device link" in stop.message
    # configure: the device link is open and read, the stream not published, cycles refused
    assert sup.transition(Transition.TRANSITION_CONFIGURE) and sup.state() == "inactive"
    report = sup.ros.wait_for(
        lambda: sup.reports[-1]["lifecycle_state"] == "inactive" and sup.samples_read() > 0 and sup.reports[-1],
        "an inactive driver reading its device",
    )
    assert report["armed"] == "False" and report["device_coils_on"] == "False"
    assert "streaming" not in report["message"] and "publishing nothing" in report["message"], report["message"]
    sup.assert_silent_for_a_second(0)
    assert not sup.joints
    refused = sup.result(sup.cycle(theta0_rad=0.0))
    assert not refused.success and NOT_ACTIVE in refused.message, refused.message
    # activate: the stream flows, a cycle energises the coils
    assert sup.transition(Transition.TRANSITION_ACTIVATE) and sup.state() == "active"
    sup.ros.wait_for(lambda: sup.blocks and sup.joints, "blocks and the stage angle")
    assert sup.report_in("active")["armed"] == "True"
    first = sup.result(sup.cycle(theta0_rad=0.3))
    assert first.success, first.message
    # deactivate in the middle of an excitation: coils off, the cycle fails, the stream stops
    running = sup.cycle(theta0_rad=0.6, repeats=2, tuning_steps=1, gap_s=1.0)
    sup.ros.wait_for(lambda: sup.states[-1].phase == Phase.EXCITING and sup.states[-1].coils_on, "an excitation")
    assert sup.transition(Transition.TRANSITION_DEACTIVATE) and sup.state() == "inactive"
    failed = sup.result(running)
    assert not failed.success and NOT_ACTIVE in failed.message, failed.message
    # A deactivate is no fault: the cycle is cancelled, the coils off, the sequencer idle.
    fault = sup.ros.wait_for(lambda: sup.states[-1].phase == Phase.IDLE and sup.states[-1], "coils off")
    assert not fault.coils_on and fault.header.stamp != sup.states[-2].header.stamp
    report = sup.report_in("inactive")
    assert report["device_coils_on"] == "False" and report["armed"] == "False"
    # No block holds a sample read after the coils went off.
    sup.assert_silent_for_a_second(sup.sample_index_of(fault))
    refused = sup.result(sup.cycle(theta0_rad=0.0))
    assert not refused.success and NOT_ACTIVE in refused.message
    # active again: cycles run again
    assert sup.transition(Transition.TRANSITION_ACTIVATE)
    again = sup.result(sup.cycle(theta0_rad=0.9))
    assert again.success, again.message
    # deactivate, cleanup (link closed), configure again, shut down from inactive
    assert sup.transition(Transition.TRANSITION_DEACTIVATE)
    assert sup.transition(Transition.TRANSITION_CLEANUP) and sup.state() == "unconfigured"
    assert "samples" not in sup.report_in("unconfigured")  # no device session any more
    assert sup.transition(Transition.TRANSITION_CONFIGURE) and sup.state() == "inactive"
    assert sup.transition(Transition.TRANSITION_INACTIVE_SHUTDOWN) and sup.state() == "finalized"
    assert not sup.transition(Transition.TRANSITION_CONFIGURE)  # finalized is final
    # Every excitation was in a cycle that ran while active, and no report outside active
    # ever saw a coil on.
    assert {s.cycle_id for s in sup.states if s.coils_on} <= {first.cycle_id, failed.cycle_id, again.cycle_id}
    assert all(r.get("device_coils_on", "False") == "False" for r in sup.reports if r["lifecycle_state"] != "active")
    process.terminate()
    assert process.wait(timeout=30) == 0, log(process)


def wait_until(condition, what: str) -> None:
    deadline = time.monotonic() + WAIT_S
    while not condition():
        assert time.monotonic() < deadline, f"gave up after {WAIT_S} s waiting for {what}"
        time.sleep(0.01)


def test_a_failing_deactivate_takes_the_error_path_and_leaves_the_coils_off(ros_context):
    node = driver.DriverNode()
    try:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS, node.lifecycle_problem
        assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
        session = node.session
        device = session.backend.device  # the streaming thread reads it
        wait_until(lambda: session.health().get("samples"), "the first samples")
        done = []
        session.start_cycle(CycleRequest(0.0), done.append)
        wait_until(lambda: device.coils_on or done, "the excitation")
        assert device.coils_on, done

        def broken(reason):
            raise RuntimeError("a bug in deactivate")

        session.disarm = broken
        assert node.trigger_deactivate() == TransitionCallbackReturn.ERROR
        assert node.lifecycle_state == "unconfigured" and node.session is None  # cleaned up
        assert not device.coils_on and done and not done[0].success
        health = node._report()
        assert health.level == DiagnosticStatus.ERROR
        assert "deactivate failed: RuntimeError: a bug in deactivate" in health.message
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS  # it can start over
        assert node._report().level == DiagnosticStatus.OK
    finally:
        node.destroy_node()


def test_a_refused_configure_leaves_the_node_unconfigured_with_the_reason(ros_context):
    node = driver.DriverNode()
    try:
        node.values = {**node.values, "backend": "serial", "serial_port": ""}
        assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
        assert node.lifecycle_state == "unconfigured" and node.session is None
        assert node.lifecycle_problem.startswith("configure refused: ")
        assert "backend serial needs the device's port" in node.lifecycle_problem
        assert node._report().values["lifecycle_state"] == "unconfigured"
    finally:
        node.destroy_node()


def test_mows_graph_leaves_the_nodes_unconfigured_for_a_supervisor(ros, supervisor, lifecycle, start):
    graph = start("mows-graph", "--unconfigured")
    assert {lifecycle.state(node.name) for node in NODES} == {"unconfigured"}, log(graph)
    assert "nodes left unconfigured" in log(graph)
    # Unconfigured nodes refuse their work with a message that names the state (asked by the
    # previous release's names, which are served as aliases).
    calibrate = ros.node.create_client(CalibrateF00, "/mows/estimator/calibrate")
    answer = supervisor.result(supervisor.call(calibrate, CalibrateF00.Request(n_ringdowns=3, timeout_s=1.0)))
    assert not answer.success and "the estimator node is unconfigured" in answer.message
    sweeps = ActionClient(ros.node, RotationSweep, "/mows/mapper/rotation_sweep")
    ros.wait_for(sweeps.server_is_ready, "the sweep action")
    goal = RotationSweep.Goal(theta0_rad=[0.0, 1.0, 2.0, 3.0, 4.0], repeats_per_angle=1)
    _, done, _ = send_goal(ros, sweeps, goal)
    assert done.status == GoalStatus.STATUS_ABORTED  # accepted, then aborted with the reason for the client
    assert done.result.message.startswith("sweep goal refused: the mapper node is unconfigured")


def test_mows_graph_configures_all_then_activates_in_data_flow_order(ros, lifecycle, start):
    graph = start("mows-graph")
    names = [node.name for node in NODES]
    # Bounded as mows-graph bounds it: configuring compiles, minutes on a loaded machine.
    ros.wait_for(lambda: "every node is active" in log(graph) or graph.poll() is not None, "bring-up", BOUND_S)
    assert {lifecycle.state(name) for name in names} == {"active"}, log(graph)
    steps = re.findall(r"^\[graph\] (configured: .*|\w+ active)$", log(graph), re.MULTILINE)
    assert steps == [f"configured: {', '.join(names)}", *(f"{name} active" for name in names)]


def test_a_driver_restarted_mid_session_keeps_the_estimator_fitting(supervisor, start):
    """A lifecycle restart (deactivate, cleanup, configure, activate) starts the simulated device's
    clock again: the estimator must start a new stream on it, not drop every block as a repeat,
    and the next cycle's fit must come as promptly as before (within 1 s of the cycle's answer,
    where it never came); cycle ids are not reused, and both nodes count the restart."""
    sup = supervisor
    fits: list[tuple[float, RingdownFit]] = []
    sup.ros.node.create_subscription(RingdownFit, "/mows/ringdown", lambda f: fits.append((time.monotonic(), f)), 100)
    estimator_reports: list[dict] = []
    sup.ros.node.create_subscription(
        DiagnosticArray,
        "/diagnostics",
        lambda a: estimator_reports.extend(
            {kv.key: kv.value for kv in s.values} for s in a.status if s.name == "/estimator"
        ),
        10,
    )
    driver_process = start(*NODES[0].command(QUICK_CYCLES, autostart=False))
    start(*NODES[1].command([]))
    active = "the estimator active (its kernels compiled)"
    sup.ros.wait_for(lambda: estimator_reports and estimator_reports[-1]["lifecycle_state"] == "active", active, 300.0)
    for transition in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE):
        assert sup.transition(transition)
    sup.ros.wait_for(lambda: sup.blocks, "the first block")
    assert sup.blocks[-1].device_epoch == 0
    sup.ros.wait_for_estimator_hearing()
    first = sup.result(sup.cycle(theta0_rad=0.3))
    assert first.success, first.message
    sup.ros.wait_for(lambda: any(f.cycle_id == first.cycle_id for _, f in fits), "the first cycle's fit")
    for transition in (
        Transition.TRANSITION_DEACTIVATE,
        Transition.TRANSITION_CLEANUP,
        Transition.TRANSITION_CONFIGURE,
        Transition.TRANSITION_ACTIVATE,
    ):
        assert sup.transition(transition)
    # The restarted device's clock: the blocks say so, and a cycle waits for its first samples.
    sup.ros.wait_for(lambda: sup.blocks and sup.blocks[-1].device_epoch == 1, "a block of the new clock")
    new_clock = "the estimator counting the restart"
    sup.ros.wait_for(lambda: estimator_reports[-1]["device_restarts"] == "1", new_clock)
    second = sup.result(sup.cycle(theta0_rad=0.6))
    answered = time.monotonic()
    assert second.success, second.message
    assert second.cycle_id > first.cycle_id  # not a second "cycle 1" on /mows/ringdown
    arrived, fit = sup.ros.wait_for(
        lambda: next(((t, f) for t, f in fits if f.cycle_id == second.cycle_id), None), "the second cycle's fit"
    )
    assert fit.status == RingdownFit.STATUS_OK, fit.message
    assert arrived - answered < 1.0, f"the fit came {arrived - answered:.1f} s after the cycle's answer"
    assert sup.report_in("active")["device_restarts"] == "1"
    assert estimator_reports[-1]["windows_before_start"] == "0"
    driver_process.terminate()
    assert driver_process.wait(timeout=30) == 0, log(driver_process)
