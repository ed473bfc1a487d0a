"""The calibrator node: the probe calibration action through a stand-in driver whose ring-down
fits come from the exact field of the calibration bench, and the supply at zero in every ending."""

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from mows_msgs.action import CalibrateProbe
from mows_msgs.msg import RingdownFit
from mows_msgs.srv import SetFieldCurrent
from std_srvs.srv import Trigger

from mows.physics.probe import Probe, calibration_record
from mows_ros.qos import RESULT_QOS
from node_processes import HeldCycles, leave_while_running, log, send_goal, serve_cycles
from sweep.calibration_bench import BENCH, bench_fits

pytestmark = pytest.mark.ros

CURRENTS = [0.0, 1.0, 2.0, -1.0, -2.0]


class StandInDriver:
    """Answers set_field_current (recording every current) and run_cycle (publishing fits of the
    bench's probe in the environment plus the supply's field at the present current)."""

    def __init__(self, ros, slow_cycles=False, supply=True, range_a=(-2.0, 2.0), probe_id=0, neighbour=None):
        self.ros, self.slow, self.supply, self.range_a = ros, slow_cycles, supply, range_a
        self.probe_id, self.neighbour, self.others = probe_id, neighbour, 0
        self.currents, self.current, self.cycle = [], 0.0, 0
        self.rng = np.random.default_rng(3)
        self.fits = ros.node.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
        ros.node.create_service(SetFieldCurrent, "driver/set_field_current", self.set_current)
        self.server = serve_cycles(ros, self.run_cycle)

    def set_current(self, request, response):
        if not self.supply:  # the driver's answer on the bag backend
            response.success, response.message = False, "supply current refused: the bag backend has no supply to set"
            response.min_current_a = response.max_current_a = float("nan")
            return response
        response.min_current_a, response.max_current_a = self.range_a
        self.currents.append(request.current_a)
        self.current = request.current_a
        response.success, response.current_a, response.message = True, request.current_a, "ok"
        return response

    def run_cycle(self, request, response):
        self.cycle += 1
        for repeat, fields in enumerate(bench_fits(self.current, request.theta0_rad, request.repeats, self.rng)):
            ok = dict(status=RingdownFit.STATUS_OK, status_name="OK", cycle_id=self.cycle, repeat_index=repeat)
            if self.neighbour is not None:  # another probe in the same window, 10 Hz higher, first
                shifted = dict(fields, frequency_hz=fields["frequency_hz"] + 10.0)
                self.fits.publish(RingdownFit(probe_id=self.neighbour, **ok, **shifted))
                self.others += 1
            self.fits.publish(RingdownFit(probe_id=self.probe_id, **ok, **fields))
        response.success, response.cycle_id, response.ringdowns_recorded = True, self.cycle, request.repeats
        return response


@pytest.fixture
def calibrator(action_server, tmp_path):
    path = tmp_path / "probe.yaml"
    client, _ = action_server(
        "calibrator", CalibrateProbe, "calibrator/calibrate_probe", f"probe_output_file:={path}", "hardware_id:=bench-3"
    )
    return client, path


def test_a_calibration_recovers_the_bench_probe_and_writes_its_file(ros, calibrator):
    client, path = calibrator
    driver = StandInDriver(ros)
    _, done, feedback = send_goal(ros, client, CalibrateProbe.Goal(currents_a=CURRENTS))
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.success, done.result.message
    # The supply is set to zero on arrival (is there one?), then stepped up at 0° and down at
    # 180° (no ramp at the turn), then back to zero.
    assert driver.currents == [0.0] + CURRENTS + CURRENTS[-2::-1] + [0.0] and done.result.supply_at_zero
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


def test_one_probe_of_several_is_calibrated_from_its_own_fits(ros, action_server, tmp_path):
    """Probe 1 is the bench's; probe 0, in the same windows, rings 10 Hz higher and its fits
    come first: taken for probe 1's, they put the calibrated spring 8 % off."""
    path = tmp_path / "probe.yaml"
    args = (f"probe_output_file:={path}", "probe_id:=1")
    client, _ = action_server("calibrator", CalibrateProbe, "calibrator/calibrate_probe", *args)
    driver = StandInDriver(ros, probe_id=1, neighbour=0)
    _, done, feedback = send_goal(ros, client, CalibrateProbe.Goal(currents_a=CURRENTS))
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.success, done.result.message
    assert Probe.from_yaml(path).spring_nm_per_rad == pytest.approx(BENCH.probe.spring_nm_per_rad, rel=0.01)
    assert feedback[-1].ringdowns == 2 * len(CURRENTS) == driver.others
    assert f"; {driver.others} ring-down fits of other probes ignored" in done.result.message


def test_cancelling_mid_calibration_ramps_the_supply_to_zero_before_the_result(ros, calibrator):
    client, path = calibrator
    driver = StandInDriver(ros)
    _, done, _ = send_goal(ros, client, CalibrateProbe.Goal(currents_a=CURRENTS), cancel_after_feedback=4)
    assert done.status == GoalStatus.STATUS_CANCELED and not done.result.success
    assert done.result.supply_at_zero and driver.currents[-1] == 0.0 and len(driver.currents) < len(CURRENTS) + 2
    assert not path.exists()


def test_goals_it_cannot_run_are_refused_with_the_reason_in_the_result(ros, calibrator):
    client, path = calibrator
    _, done, _ = send_goal(ros, client, CalibrateProbe.Goal(wiring="sideways"))
    assert done.status == GoalStatus.STATUS_ABORTED and "sideways" in done.result.message
    # A driver without a supply (a recording, a device with none) refuses set_field_current:
    # the goal ends at once with its reason, before any cycle.
    driver = StandInDriver(ros, supply=False)
    _, done, feedback = send_goal(ros, client, CalibrateProbe.Goal(currents_a=CURRENTS))
    assert done.status == GoalStatus.STATUS_ABORTED and not feedback and driver.cycle == 0
    assert done.result.message == (
        "calibration goal refused: the driver's supply cannot be set: supply current refused: the bag backend "
        "has no supply to set"
    )
    assert not path.exists()


def test_a_plan_a_unipolar_supply_cannot_give_is_refused_before_any_current_is_set(ros, calibrator):
    """The driver's answer to the first set-point (zero) states its supply's range, 0 … 2 A."""
    client, path = calibrator
    driver = StandInDriver(ros, range_a=(0.0, 2.0))
    _, done, feedback = send_goal(ros, client, CalibrateProbe.Goal(currents_a=CURRENTS))
    assert done.status == GoalStatus.STATUS_ABORTED and not feedback and driver.cycle == 0
    assert driver.currents == [0.0]
    assert done.result.message.startswith(
        "calibration goal refused: supply current -1 A of the plan is outside the supply's range 0 … +2 A; "
        "a unipolar supply gets the field's other sign from θ0 + 180°"
    ), done.result.message
    assert not path.exists()


def test_a_manual_stage_waits_for_the_operator_before_each_turn(ros, action_server, tmp_path):
    client, _ = action_server(
        "calibrator",
        CalibrateProbe,
        "mows/calibrator/calibrate_probe",
        f"probe_output_file:={tmp_path / 'p.yaml'}",
        "orientation:=manual",
    )
    driver = StandInDriver(ros)
    confirm = ros.node.create_client(Trigger, "calibrator/confirm_orientation")
    ros.wait_for(lambda: confirm.service_is_ready(), "the confirm_orientation service")
    feedback = []
    sent = client.send_goal_async(
        CalibrateProbe.Goal(currents_a=CURRENTS), feedback_callback=lambda f: feedback.append(f.feedback)
    )
    handle = ros.wait_for(lambda: sent.done() and sent.result(), "the goal's answer")
    result = handle.get_result_async()

    def prompt(k):
        prompts = [f for f in feedback if f.message.startswith("turn the probe")]
        return len(prompts) > k and prompts[k]

    for k in range(2):  # every current at 0°, then every current at 180°: one turn each
        asked = ros.wait_for(lambda k=k: prompt(k), f"the prompt for turn {k}")
        assert asked.message == f"turn the probe to θ0 = {180 * k}° and confirm"
        assert driver.cycle == k * len(CURRENTS)  # the cycle waits for the operator
        future = confirm.call_async(Trigger.Request())
        assert ros.wait_for(lambda f=future: f.done() and f.result(), "the confirmation").success
    done = ros.wait_for(lambda: result.done() and result.result(), "the calibration's result")
    assert done.result.success, done.result.message
    assert driver.cycle == 2 * len(CURRENTS) and done.result.supply_at_zero
    assert len([f for f in feedback if f.message.startswith("turn the probe")]) == 2


class HeldSupply(HeldCycles):
    """A stand-in driver whose cycles run until they are cancelled, with a supply that records
    every current set."""

    def __init__(self, ros):
        super().__init__(ros)
        self.currents = []
        ros.node.create_service(SetFieldCurrent, "driver/set_field_current", self.set_current)

    def set_current(self, request, response):
        self.currents.append(request.current_a)
        response.min_current_a, response.max_current_a = -2.0, 2.0
        response.success, response.current_a, response.message = True, request.current_a, "ok"
        return response


def test_a_calibration_whose_client_leaves_is_cancelled_with_the_supply_at_zero(ros, action_server, start, tmp_path):
    """Ctrl-C on the calibration's only client: nobody waits for it, so the calibrator cancels
    it and the cycle it is waiting for, ramps the supply to zero, writes no probe file, and
    says so in its log and on /diagnostics."""
    path = tmp_path / "probe.yaml"
    fixture_client, process = action_server(
        "calibrator", CalibrateProbe, "calibrator/calibrate_probe", f"probe_output_file:={path}"
    )
    fixture_client.destroy()  # a client of the action that stays would be one that may wait
    driver = HeldSupply(ros)
    diagnostics = ros.diagnostics_of("/calibrator")
    goal = f"CalibrateProbe.Goal(currents_a={CURRENTS})"
    leave_while_running(ros, start, driver, "CalibrateProbe", "/calibrator/calibrate_probe", goal)
    reason = "every node that asked for it through /calibrator/calibrate_probe/_action/send_goal has left"
    ros.wait_for(lambda: f"calibration cancelled, its cycle with it: {reason}" in log(process), "the log line")
    ros.wait_for(lambda: diagnostics.get("cancels") == "1", "the cancel counted on /diagnostics")
    assert diagnostics["last_ending"].startswith("cancelled"), diagnostics
    assert driver.currents[0] == 0.0 and driver.currents[-1] == 0.0, driver.currents  # zero at the start and end
    assert len(driver.goals) == 1 and not path.exists()  # no cycle after it, no probe file
    ros.wait_for(lambda: diagnostics.get("state") == "idle", "the calibrator free again")
