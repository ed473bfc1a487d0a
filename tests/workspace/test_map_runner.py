"""The workspace map's run without ROS (:class:`MapRunner`): it asks the arm for the plan's
poses, sweeps once the arm reports each there and still, feeds each accepted sweep to the plan
and fits the map of them; a refused pose is reported and logged, and five in a row end the map;
a sweep that fails ends it; a cancel ends it with no further sweep and no refusal; an arm whose
last joint turns the probe is asked for each orientation."""

import dataclasses
import math

import numpy as np
import pytest

from mows.physics.field import PointDipole
from mows.physics.probe import PAPER_PROBE
from mows.sweep.events import SweepGoal, SweepMap, SweepOutcome
from mows.sweep.record import SweepPoint, SweepRecord
from mows.workspace.arm import NS_PER_S, Reach, StampedPose
from mows.workspace.mapping import MapSettings, PosePlan, PoseWatch, sweep_observations, turned, workspace_map
from mows.workspace.poses import PoseError
from mows.workspace.runner import REFUSALS_IN_A_ROW, MapRunner, MapStep
from mows.workspace.simulated import SweepPose, simulate_sweep

SETTINGS = MapSettings((0.3, 0.0, 0.0), 0.015, PoseError(1e-4, math.radians(0.01)), Reach((0, 0, 0), 0.1, 0.6))
SOURCE = PointDipole([0.6, 0.2, 0.1], [0.2, -0.1, 0.1])
GOAL = SweepGoal(theta0_rad=(0.0, 1.0, 2.0), repeats_per_angle=2)
TIMEOUT_S = 3.0
MOVE_REFUSAL = "the arm did not report the pose asked for within 3 s"


def same(a: StampedPose, b: StampedPose) -> bool:
    return (a.stamp_ns, a.frame_id) == (b.stamp_ns, b.frame_id) and np.array_equal(
        np.r_[a.position_m, a.orientation_xyzw], np.r_[b.position_m, b.orientation_xyzw]
    )


def watch(turns=False):
    return PoseWatch(1e-4, math.radians(0.05), 0.5, SETTINGS.reach, turns)


def started(count=4, turns=False, settings=SETTINGS) -> tuple[MapRunner, MapStep]:
    runner = MapRunner(settings, PAPER_PROBE, watch(turns), count, GOAL)
    return runner, runner.begin()


def at(pose: StampedPose, time_s: float, shift_m=0.0) -> StampedPose:
    return dataclasses.replace(pose, stamp_ns=int(time_s * NS_PER_S), position_m=pose.position_m + [0, shift_m, 0])


def arrive(runner: MapRunner, target: StampedPose, time_s: float) -> MapStep:
    """The arm reports ``target`` twice (still): the runner's step once it says the arm is there."""
    runner.watch.on_pose(at(target, time_s))
    runner.watch.on_pose(at(target, time_s + 0.02))
    assert runner.arrived()
    return runner.on_arrived(int((time_s + 0.05) * NS_PER_S))


def outcome_at(pose: StampedPose, sweep_id: int, stamp_ns: int) -> SweepOutcome:
    decomposition = simulate_sweep(
        SOURCE, SweepPose(pose.position_m, pose.plane), PAPER_PROBE, np.random.default_rng(sweep_id)
    )
    record = SweepRecord([SweepPoint(0.0, 90.0, 1e-3, 0.1, 1e-3, 0.1, 0.1, 2.0, 0.0, stamp_ns=stamp_ns)])
    return SweepOutcome(True, "decomposed", maps=(SweepMap(sweep_id, decomposition, record, PAPER_PROBE.f00_hz),))


def sweep_there(runner: MapRunner, step: MapStep, time_s: float, sweep_id: int, moved_m=0.0) -> MapStep:
    """Arrive at ``step``'s pose, sweep there (the arm moved by ``moved_m`` meanwhile): the next step."""
    swept = arrive(runner, step.move, time_s)
    assert swept.sweep == GOAL and swept.move is None
    runner.watch.on_pose(at(step.move, time_s + 10.0, moved_m))
    return runner.on_swept(outcome_at(step.move, sweep_id, int(time_s * NS_PER_S)), int((time_s + 10.05) * NS_PER_S))


def time_out(runner: MapRunner, times: int) -> list[MapStep]:
    return [runner.move_timed_out(TIMEOUT_S) for _ in range(times)]


def test_a_map_sweeps_where_its_plan_asks_and_fits_the_sweeps_at_the_reported_poses():
    runner, step = started(count=4)
    plan, sweeps = PosePlan(SETTINGS, PAPER_PROBE), []
    for k in range(4):
        assert same(step.move, plan.next_goal())
        reported = at(step.move, 20.0 * k + 0.02)  # the report that found the arm still: the sweep's pose
        step = sweep_there(runner, step, 20.0 * k, 100 + k)
        assert step.feedback.sweep_index == k and step.feedback.n_sweeps == 4
        assert step.feedback.accepted and same(step.feedback.pose, reported) and not step.warning
        sweeps.append((step.feedback.outcome.map.decomposition, reported))
        plan.swept(sweep_observations(sweeps[-1:], PAPER_PROBE, SETTINGS)[0])
    assert step.move is None and step.fit is not None
    end = runner.on_fitted(step.fit()).finished
    expected = workspace_map(sweeps, PAPER_PROBE, SETTINGS)  # the map `mows map BAG` makes of them
    assert end.success and end.message == expected.report() and end.message.startswith("workspace map of 4 sweeps")
    assert np.array_equal(end.map.model.coefficients, expected.model.coefficients)
    assert end.sweep_ids == (100, 101, 102, 103) and end.stamp_ns == int(60.0 * NS_PER_S)


def test_five_poses_refused_in_a_row_end_the_map_with_the_last_reason():
    runner, _ = started()
    steps = time_out(runner, REFUSALS_IN_A_ROW)
    for step in steps:
        assert step.warning == f"pose refused: {MOVE_REFUSAL}"
        assert not step.feedback.accepted and step.feedback.refusal == MOVE_REFUSAL and step.feedback.sweep_index == 0
    assert all(step.finished is None and step.move is not None for step in steps[:-1])
    assert steps[-1].move is None
    assert steps[-1].finished.message == f"5 poses in a row refused, the last: {MOVE_REFUSAL}"
    assert not steps[-1].finished.success


def test_an_accepted_sweep_starts_the_count_of_refusals_again():
    runner, _ = started()
    step = time_out(runner, REFUSALS_IN_A_ROW - 1)[-1]
    step = sweep_there(runner, step, 0.0, 1)
    assert step.feedback.accepted
    steps = time_out(runner, REFUSALS_IN_A_ROW - 1)
    assert all(s.finished is None for s in steps) and steps[-1].feedback.sweep_index == 1


def test_a_pose_that_cannot_stand_for_a_sweep_is_refused_before_any_sweep():
    runner, step = started()
    runner.watch.on_pose(at(step.move, 1.0))
    runner.watch.on_pose(at(step.move, 1.02))
    step = runner.on_arrived(int(5.0 * NS_PER_S))  # the arm's report is 4 s old
    assert step.sweep is None and step.move is not None
    assert "stale pose" in step.feedback.refusal and step.warning == f"pose refused: {step.feedback.refusal}"


def test_a_sweep_during_which_the_arm_moved_is_refused_and_left_out_of_the_map():
    runner, step = started(count=2)
    step = sweep_there(runner, step, 0.0, 1, moved_m=0.5e-3)
    assert "the arm moved during the sweep's ring-downs" in step.feedback.refusal and step.warning
    assert same(step.feedback.pose, runner.watch.latest) and step.move is not None
    step = sweep_there(runner, step, 20.0, 2)
    assert step.feedback.accepted and step.feedback.sweep_index == 0 and step.fit is None


def test_a_sweep_that_fails_ends_the_map_reported_but_not_as_a_refused_pose():
    runner, step = started()
    arrive(runner, step.move, 0.0)
    step = runner.on_swept(SweepOutcome(False, "the driver's cycle 7 failed"), int(10.0 * NS_PER_S))
    assert step.feedback.refusal == "the driver's cycle 7 failed" and not step.warning and step.move is None
    assert step.finished.message == "workspace map failed: the driver's cycle 7 failed" and not step.finished.success


@pytest.mark.parametrize("arm", ["arrives", "times out"])
def test_a_map_cancelled_during_a_move_takes_no_sweep_and_refuses_no_pose(arm):
    runner, step = started()
    runner.watch.on_pose(at(step.move, 0.0))
    runner.watch.on_pose(at(step.move, 0.02))
    runner.cancel()
    step = runner.on_arrived(int(0.05 * NS_PER_S)) if arm == "arrives" else runner.move_timed_out(TIMEOUT_S)
    assert step.sweep is None and step.move is None and step.feedback is None and not step.warning
    assert step.finished.message == "workspace map cancelled" and not step.finished.success


def test_a_map_cancelled_during_a_sweep_ends_without_reporting_its_pose():
    runner, step = started()
    arrive(runner, step.move, 0.0)
    runner.cancel()
    step = runner.on_swept(SweepOutcome(False, "cancelled before orientation 1", cancelled=True), 10 * NS_PER_S)
    assert step.feedback is None and not step.warning and step.move is None
    assert step.finished.message == "workspace map cancelled"


def test_a_map_being_fitted_is_not_cancelled():
    runner, step = started(count=4)
    for k in range(4):
        step = sweep_there(runner, step, 20.0 * k, k)
    runner.cancel()
    assert runner.on_fitted(step.fit()).finished.success


def test_an_arm_that_turns_the_probe_is_asked_for_each_orientation_about_the_poses_normal():
    runner, step = started(turns=True)
    target = step.move
    swept = arrive(runner, target, 0.0)
    assert swept.sweep == GOAL and swept.turns
    quarter = runner.turn(math.pi / 2)
    assert same(quarter, turned(target, math.pi / 2)) and not runner.arrived()
    runner.watch.on_pose(at(quarter, 1.0))
    runner.watch.on_pose(at(quarter, 1.02))
    assert runner.arrived()
    assert runner.turn_timed_out(TIMEOUT_S) == "the arm did not turn the probe to θ0 = 90° within 3 s"
    runner, step = started(turns=False)
    assert not arrive(runner, step.move, 0.0).turns


def test_a_workspace_out_of_the_arms_reach_fails_at_once():
    far = dataclasses.replace(SETTINGS, reach=Reach((0, 0, 0), 0.1, 0.2))
    step = started(settings=far)[1]
    assert step.move is None and "workspace map failed: no pose left within the arm's reach" in step.finished.message
