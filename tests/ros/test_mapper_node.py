"""The mapper node: a rotation sweep through a stand-in driver that answers its measurement-cycle goals with
ring-down fits computed from the exact field of a scenario, decomposed into B and G."""

import math

import numpy as np
import pytest
from action_msgs.msg import GoalStatus
from action_msgs.srv import CancelGoal
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from mows_msgs.action import RotationSweep
from mows_msgs.msg import ModelReport, RingdownFit, SweepDecomposition
from std_srvs.srv import Trigger

from mows.lab import reference_at
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE
from mows.sim.scenario import load_scenario
from mows.sweep.decomposition import DecompositionStatus
from mows_ros.qos import MAP_QOS, RESULT_QOS
from node_processes import HeldCycles, leave_while_running, log, send_goal, serve_cycles

pytestmark = pytest.mark.ros

SCENARIO = "helmholtz"
STD_HZ = 5e-4
ANGLES = np.radians(np.arange(0.0, 360.0, 30.0))


class StandInDriver:
    """Answers measurement-cycle goals: publishes `repeats` fits of the cycle, f from the full potential."""

    def __init__(self, ros, fail=False, tuning=False, bad_fits=False):
        scenario = load_scenario(SCENARIO)
        self.source, self.fail, self.tuning, self.bad_fits = scenario.environment.source, fail, tuning, bad_fits
        self.fits = ros.node.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
        self.server = serve_cycles(ros, self.run_cycle)
        self.cycle, self.rng = 0, np.random.default_rng(0)

    def run_cycle(self, request, response):
        if self.fail:
            response.success, response.message = False, "coil current above the cap"
            return response
        self.cycle += 1
        pose = Pose(theta0_rad=request.theta0_rad)
        f = float(ArcPotential.from_source(PAPER_PROBE, self.source, pose).frequency_hz())
        # With ``tuning`` the estimator also fits the cycle's tuning ring-down, 1 Hz off resonance.
        for repeat, tuning in [(0, True)] * self.tuning + [(r, False) for r in range(request.repeats)]:
            measured = f + STD_HZ * self.rng.standard_normal() + tuning
            status, name = (
                (RingdownFit.STATUS_NOT_CONVERGED, "NOT_CONVERGED") if self.bad_fits else (RingdownFit.STATUS_OK, "OK")
            )
            msg = RingdownFit(
                cycle_id=self.cycle,
                repeat_index=repeat,
                tuning=tuning,
                status=status,
                status_name=name,
                theta0_rad=request.theta0_rad,
                frequency_hz=measured,
                frequency_std_hz=STD_HZ,
                frequency_shift_hz=measured - PAPER_PROBE.f00_hz,
                frequency_shift_std_hz=STD_HZ,
                amplitude_rad=math.radians(2.0),
                damping_per_s=1.8,
                duration_s=0.5,
            )
            # Today's epoch to the nanosecond: float seconds would be ~100 ns off.
            msg.header.stamp.sec, msg.header.stamp.nanosec = 1_763_000_000 + self.cycle, 123_456_789 + repeat
            self.fits.publish(msg)
        response.success, response.cycle_id, response.ringdowns_recorded = True, self.cycle, request.repeats
        return response


@pytest.fixture
def mapper(action_server):
    return action_server(
        "mapper", RotationSweep, "mapper/rotation_sweep", f"reference_scenario:={SCENARIO}", "lab_auto:=false"
    )


def sweep(ros, client, **goal):
    return send_goal(ros, client, RotationSweep.Goal(**goal))


def test_a_sweep_recovers_the_field_and_reports_on_the_model(ros, mapper):
    client, _ = mapper
    StandInDriver(ros, tuning=True)  # tuning ring-downs are not measurements: the sweep leaves them out
    maps, reports = [], []
    ros.node.create_subscription(SweepDecomposition, "mows/sweep", maps.append, MAP_QOS)
    ros.node.create_subscription(ModelReport, "mows/model_report", reports.append, MAP_QOS)
    _, done, feedback = sweep(ros, client, theta0_rad=ANGLES.tolist(), repeats_per_angle=2)
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.success, done.result.message
    assert [f.angle_index for f in feedback] == list(range(len(ANGLES)))
    assert all(f.n_ok == 2 and len(f.fits) == 2 for f in feedback)
    d = done.result.decomposition
    truth, _ = reference_at(SCENARIO)
    sigma = np.sqrt(np.diag(np.reshape(d.field_covariance_t2, (2, 2))))
    assert np.all(np.abs(np.array(d.field_t) - truth[:2]) < 4 * sigma), (d.field_t, truth, sigma)
    assert d.model == "first_principles" and d.n_points == 2 * len(ANGLES) and d.chi2_dof < 2
    ros.wait_for(lambda: maps and reports, "the map and the model report")
    np.testing.assert_array_equal(maps[0].field_t, d.field_t)
    # The map is stamped with its last ring-down, integer nanoseconds end to end.
    assert (d.header.stamp.sec, d.header.stamp.nanosec) == (1_763_000_000 + len(ANGLES), 123_456_789 + 1)
    assert reports[0].n == 2 * len(ANGLES) and reports[0].verdict in (
        "adequate",
        "effect_missing",
        "unexplained_structure",
    )
    # A map is latched: a subscriber that comes later still gets it.
    late = []
    ros.node.create_subscription(SweepDecomposition, "mows/sweep", late.append, MAP_QOS)
    ros.wait_for(lambda: late, "the latched map")


def refused(done, why: str) -> bool:
    """Whether a goal was accepted, then aborted at once with ``why`` in its result's message:
    what a client sees of a refusal (a rejected goal would only say "Goal was rejected")."""
    message = done.result.message
    return done.status == GoalStatus.STATUS_ABORTED and message.startswith("sweep goal refused") and why in message


def test_bad_goals_are_refused_with_the_reason_in_the_result(ros, mapper):
    client, _ = mapper
    _, done, _ = sweep(ros, client, theta0_rad=[0.0, math.nan])
    assert refused(done, "not all finite"), done.result.message
    _, done, _ = sweep(ros, client, theta0_rad=ANGLES.tolist(), model="paper")
    assert refused(done, "'paper' is not one of"), done.result.message
    # The parameter's own limits (repeats_per_angle: 1-100) hold for a goal too.
    _, done, _ = sweep(ros, client, theta0_rad=ANGLES.tolist(), repeats_per_angle=100000)
    assert refused(done, "repeats_per_angle=100000 is outside [1, 100]"), done.result.message
    # Four orientations cannot separate field from gradient: refused on arrival, not after
    # a sweep's worth of cycles (no driver is there to run one).
    _, done, _ = sweep(ros, client, theta0_rad=ANGLES[:4].tolist())
    assert refused(done, "orientations"), done.result.message


def test_one_sweep_at_a_time(ros, mapper):
    client, _ = mapper
    StandInDriver(ros)
    goals = [
        client.send_goal_async(RotationSweep.Goal(theta0_rad=ANGLES.tolist(), repeats_per_angle=1)) for _ in range(2)
    ]
    handles = ros.wait_for(lambda: all(g.done() for g in goals) and [g.result() for g in goals], "both answers")
    results = [h.get_result_async() for h in handles]
    done = ros.wait_for(lambda: all(r.done() for r in results) and [r.result() for r in results], "both results")
    assert sum(d.result.success for d in done) == 1
    assert any(refused(d, "another sweep is still running") for d in done)
    assert next(d for d in done if d.result.success).result.decomposition.n_points == len(ANGLES)


def test_a_failed_sweep_publishes_neither_map_nor_model_report_and_warns(ros, mapper):
    client, _ = mapper
    driver = StandInDriver(ros, bad_fits=True)
    mapper_status: dict = {}
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics", lambda a: mapper_status.update((s.name, s) for s in a.status), 10
    )
    maps, reports = [], []
    ros.node.create_subscription(SweepDecomposition, "mows/sweep", maps.append, MAP_QOS)
    ros.node.create_subscription(ModelReport, "mows/model_report", reports.append, MAP_QOS)
    _, done, _ = sweep(ros, client, theta0_rad=ANGLES[:5].tolist(), repeats_per_angle=1)
    assert done.status == GoalStatus.STATUS_ABORTED and "no successful ring-down" in done.result.message
    failed = done.result.decomposition
    assert DecompositionStatus(failed.status) is not DecompositionStatus.OK and failed.message == done.result.message
    warned = ros.wait_for(
        lambda: (s := mapper_status.get("/mapper")) is not None and s.level == DiagnosticStatus.WARN and s,
        "the mapper's warning",
    )
    assert "the last sweep failed: " in warned.message and "no successful ring-down" in warned.message
    # Then a good sweep: its map and report are the first the topics carry (reliable, in order).
    driver.bad_fits = False
    _, done, _ = sweep(ros, client, theta0_rad=ANGLES.tolist(), repeats_per_angle=1)
    assert done.result.success, done.result.message
    ros.wait_for(lambda: maps and reports, "the good sweep's map and report")
    assert [m.sweep_id for m in maps] == [2] and [r.sweep_id for r in reports] == [2]
    assert np.all(np.isfinite(maps[0].field_t))
    ros.wait_for(lambda: mapper_status["/mapper"].level == DiagnosticStatus.OK, "the warning to clear")


def test_a_failing_driver_aborts_the_sweep_with_its_reason(ros, mapper):
    client, process = mapper
    StandInDriver(ros, fail=True)
    _, done, _ = sweep(ros, client, theta0_rad=ANGLES.tolist(), repeats_per_angle=1)
    assert done.status == GoalStatus.STATUS_ABORTED
    assert "above the cap" in done.result.message and not done.result.success
    assert process.poll() is None


def test_an_adaptive_goal_reaches_its_target(ros, mapper):
    client, _ = mapper
    StandInDriver(ros)
    _, done, feedback = sweep(ros, client, target="B", target_field_std_t=100e-9)
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.success, done.result.message
    d = done.result.decomposition
    sigma = np.sqrt(np.diag(np.reshape(d.field_covariance_t2, (2, 2))))
    truth, _ = reference_at(SCENARIO)
    assert np.all(sigma <= 100e-9) and np.all(np.abs(np.array(d.field_t) - truth[:2]) < 4 * sigma)
    assert len({round(f.theta0_rad, 6) for f in feedback}) >= 5  # the orientations it chose
    _, done, _ = sweep(ros, client, target="bz")
    assert refused(done, "bz"), done.result.message


def test_a_manual_stage_waits_for_the_operator_at_each_orientation(ros, action_server):
    client, _ = action_server("mapper", RotationSweep, "mows/mapper/rotation_sweep", "orientation:=manual")
    driver = StandInDriver(ros)
    confirm = ros.node.create_client(Trigger, "mapper/confirm_orientation")
    ros.wait_for(lambda: confirm.service_is_ready(), "the confirm_orientation service")

    def call_confirm():
        future = confirm.call_async(Trigger.Request())
        return ros.wait_for(lambda: future.done() and future.result(), "the confirmation's answer")

    assert not call_confirm().success  # no sweep: nothing to confirm
    angles = ANGLES[::2].tolist()
    feedback = []
    sent = client.send_goal_async(
        RotationSweep.Goal(theta0_rad=angles, repeats_per_angle=1),
        feedback_callback=lambda f: feedback.append(f.feedback),
    )
    handle = ros.wait_for(lambda: sent.done() and sent.result(), "the goal's answer")
    result = handle.get_result_async()

    def prompt(k):
        prompts = [f for f in feedback if f.operator_prompt]
        return len(prompts) > k and prompts[k]

    for k, theta0 in enumerate(angles):
        asked = ros.wait_for(lambda k=k: prompt(k), f"the prompt for orientation {k}")
        assert asked.operator_prompt == f"turn the probe to θ0 = {math.degrees(theta0):g}° and confirm"
        assert asked.theta0_rad == theta0 and math.isnan(asked.frequency_shift_hz)
        assert driver.cycle == k  # the cycle waits for the operator
        answer = call_confirm()
        assert answer.success and answer.message == f"θ0 = {math.degrees(theta0):g}° confirmed"
    done = ros.wait_for(lambda: result.done() and result.result(), "the sweep's result")
    assert done.result.success, done.result.message
    assert driver.cycle == len(angles)


def test_a_sweep_whose_client_leaves_is_cancelled_with_its_cycle_logged_and_counted(ros, mapper, start):
    """Ctrl-C on the sweep's only client: nobody waits for the sweep, so the mapper cancels it
    and the cycle it is waiting for, says so in its log and counts it on /diagnostics."""
    fixture_client, process = mapper
    fixture_client.destroy()  # a client of the sweep action that stays would be one that may wait
    driver = HeldCycles(ros)
    diagnostics = ros.diagnostics_of("/mapper")
    goal = "RotationSweep.Goal(theta0_rad=[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], repeats_per_angle=1)"
    leave_while_running(ros, start, driver, "RotationSweep", "/mapper/rotation_sweep", goal)
    reason = "every node that asked for it through /mapper/rotation_sweep/_action/send_goal has left"
    ros.wait_for(lambda: f"sweep cancelled, its cycle with it: {reason}" in log(process), "the log line")
    ros.wait_for(lambda: diagnostics.get("cancels") == "1", "the cancel counted on /diagnostics")
    assert (
        diagnostics["last_cancel"].startswith("cancelled during orientation 0") and reason in diagnostics["last_cancel"]
    )
    assert len(driver.goals) == 1  # no cycle after it
    ros.wait_for(lambda: diagnostics.get("state") == "idle", "the mapper free again")


def test_a_cancel_that_comes_after_the_sweep_ended_leaves_the_mapper_as_it_was(ros, mapper):
    """The client's cancel arrives once the last cycle's fits are in and the map is out (a
    Ctrl-C a moment too late): it is refused as too late, nothing is counted as cancelled, and
    the next sweep runs from a clean state."""
    client, process = mapper
    StandInDriver(ros)
    diagnostics = ros.diagnostics_of("/mapper")
    handle, done, _ = sweep(ros, client, theta0_rad=ANGLES.tolist(), repeats_per_angle=1)
    assert done.status == GoalStatus.STATUS_SUCCEEDED, done.result.message
    answer = handle.cancel_goal_async()
    refusal = ros.wait_for(lambda: answer.done() and answer.result(), "the answer to the late cancel")
    assert refusal.return_code == CancelGoal.Response.ERROR_GOAL_TERMINATED and not refusal.goals_canceling
    ros.wait_for(lambda: diagnostics.get("sweeps") == "1" and diagnostics["state"] == "idle", "the mapper idle")
    assert diagnostics["cancels"] == "0" and diagnostics["last_cancel"] == "", diagnostics
    _, again, _ = sweep(ros, client, theta0_rad=ANGLES.tolist(), repeats_per_angle=1)
    assert again.status == GoalStatus.STATUS_SUCCEEDED, again.result.message
    assert "cancelled" not in log(process)
