"""The calibrator node: the probe calibration action through a stand-in driver whose ring-down
fits come from the exact field of the calibration bench, and the supply at zero in every ending."""

import math
import subprocess

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from mows_msgs.action import CalibrateProbe
from mows_msgs.msg import RingdownFit
from mows_msgs.srv import RunCycle, SetFieldCurrent
from rclpy.action import ActionClient

from mows.estimate.ringdown import SETTLE_S
from mows.lab.synth import true_frequency_hz
from mows.physics.field import SumSource
from mows.physics.probe import Probe, calibration_record
from mows.sim.scenario import load_scenario
from mows_bringup.graph import NODES
from mows_ros.qos import RESULT_QOS

pytestmark = pytest.mark.ros

BENCH = load_scenario("calibration")
STD_HZ = 3e-4
CURRENTS = [0.0, 1.0, 2.0, -1.0, -2.0]


class StandInDriver:
    """Answers set_field_current (recording every current) and run_cycle (publishing fits of the
    bench's probe in the environment plus the supply's field at the present current)."""

    def __init__(self, ros, slow_cycles=False):
        self.ros, self.slow = ros, slow_cycles
        self.currents, self.current, self.cycle = [], 0.0, 0
        self.rng = np.random.default_rng(3)
        self.fits = ros.node.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
        ros.node.create_service(SetFieldCurrent, "mows/driver/set_field_current", self.set_current)
        ros.node.create_service(RunCycle, "mows/driver/run_cycle", self.run_cycle)

    def set_current(self, request, response):
        self.currents.append(request.current_a)
        self.current = request.current_a
        response.success, response.current_a, response.message = True, request.current_a, "ok"
        return response

    def run_cycle(self, request, response):
        self.cycle += 1
        source = (
            SumSource((BENCH.environment.source, BENCH.supply.source.scaled(self.current)))
            if self.current
            else BENCH.environment.source
        )
        start = BENCH.probe.theta_stop_rad * math.exp(-BENCH.probe.damping_per_s * SETTLE_S)
        truth = float(true_frequency_hz(BENCH.probe, source, [request.theta0_rad], start, duration_s=0.5)[0])
        for repeat in range(request.repeats):
            f = truth + STD_HZ * self.rng.standard_normal()
            self.fits.publish(
                RingdownFit(
                    cycle_id=self.cycle,
                    repeat_index=repeat,
                    status=RingdownFit.STATUS_OK,
                    status_name="OK",
                    theta0_rad=request.theta0_rad,
                    frequency_hz=f,
                    frequency_std_hz=STD_HZ,
                    amplitude_rad=start,
                    damping_per_s=1.8,
                    duration_s=0.5,
                )
            )
        response.success, response.cycle_id, response.ringdowns_recorded = True, self.cycle, request.repeats
        return response


@pytest.fixture
def calibrator(ros, tmp_path):
    node = next(n for n in NODES if n.name == "calibrator")
    log_path = tmp_path / "calibrator.log"
    process = subprocess.Popen(
        node.command(["-p", f"probe_file:={tmp_path / 'probe.yaml'}", "-p", "hardware_id:=bench-3"]),
        stdout=open(log_path, "w"),
        stderr=subprocess.STDOUT,
    )
    client = ActionClient(ros.node, CalibrateProbe, "mows/calibrator/calibrate_probe")
    ros.wait_for(lambda: client.server_is_ready(), "the calibration action server")
    yield client, tmp_path / "probe.yaml"
    process.terminate()
    try:
        code = process.wait(timeout=30)
    except subprocess.TimeoutExpired:
        process.kill()
        code = process.wait()
    assert code == 0, log_path.read_text()


def send(ros, client, goal, cancel_after_feedback=None):
    feedback = []
    sent = client.send_goal_async(goal, feedback_callback=lambda f: feedback.append(f.feedback))
    handle = ros.wait_for(lambda: sent.done() and sent.result(), "the goal to be answered")
    assert handle.accepted
    if cancel_after_feedback is not None:
        ros.wait_for(lambda: len(feedback) >= cancel_after_feedback, "feedback")
        handle.cancel_goal_async()
    result = handle.get_result_async()
    return ros.wait_for(lambda: result.done() and result.result(), "the calibration result"), feedback


def test_a_calibration_recovers_the_bench_probe_and_writes_its_file(ros, calibrator):
    client, path = calibrator
    driver = StandInDriver(ros)
    done, feedback = send(ros, client, CalibrateProbe.Goal(currents_a=CURRENTS))
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.success, done.result.message
    assert driver.currents == CURRENTS + [0.0] and done.result.supply_at_zero
    assert feedback[-1].steps == 2 * len(CURRENTS) and feedback[-1].ringdowns == 2 * len(CURRENTS)
    probe = Probe.from_yaml(done.result.probe_file)
    assert done.result.probe_file == str(path)
    assert probe.spring_nm_per_rad == pytest.approx(BENCH.probe.spring_nm_per_rad, rel=0.01)
    assert probe.inertia_kgm2 == pytest.approx(BENCH.probe.inertia_kgm2, rel=0.01)
    assert probe.lever_m == pytest.approx(BENCH.probe.lever_m, rel=0.03)
    record = calibration_record(path)
    assert record["hardware_id"] == "bench-3"
    values = dict(zip(done.result.names, done.result.values))
    assert values["f00_hz"] == pytest.approx(record["constants"]["f00_hz"]["value"])


def test_cancelling_mid_calibration_ramps_the_supply_to_zero_before_the_result(ros, calibrator):
    client, path = calibrator
    driver = StandInDriver(ros)
    done, _ = send(ros, client, CalibrateProbe.Goal(currents_a=CURRENTS), cancel_after_feedback=4)
    assert done.status == GoalStatus.STATUS_CANCELED and not done.result.success
    assert done.result.supply_at_zero and driver.currents[-1] == 0.0 and len(driver.currents) < len(CURRENTS) + 1
    assert not path.exists()


def test_a_goal_with_a_bad_wiring_is_refused(ros, calibrator):
    client, _ = calibrator
    sent = client.send_goal_async(CalibrateProbe.Goal(wiring="sideways"))
    handle = ros.wait_for(lambda: sent.done() and sent.result(), "the goal to be answered")
    assert not handle.accepted
