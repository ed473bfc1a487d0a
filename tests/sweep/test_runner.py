"""The rotation sweep as a state machine (mows.sweep.runner), driven without ROS: a stand-in
driver answers its cycle calls with fits whose frequencies come from the full potential of a
known uniform field; the runner's decomposition must recover that field."""

import math

import numpy as np
import pytest

from mows.estimate.probe_set import own_probe_entry
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.decomposition import Decomposition, DecompositionStatus
from mows.sweep.events import CycleAnswer, SweepFit, SweepGoal, SweepSettings
from mows.sweep.operator import turn_prompt
from mows.sweep.record import SweepPoint
from mows.sweep.runner import SweepRunner

OWN = (own_probe_entry(P),)  # the runner's probe: a set of one

FIELD_T = np.array([30e-6, -20e-6, 0.0])
STD_HZ = 5e-4
ANGLES = tuple(np.radians(np.arange(0.0, 360.0, 30.0)))


class StandIn:
    """Runs the runner's cycle calls: fits of each cycle (OK, at the exact frequency plus noise)."""

    def __init__(self, seed=0):
        self.source = UniformField(FIELD_T)
        self.rng = np.random.default_rng(seed)
        self.cycle_id = 0

    def fit(self, theta0_rad, ok=True, tuning=False, cycle_id=None):
        f = float(ArcPotential.from_source(P, self.source, Pose(theta0_rad=theta0_rad)).frequency_hz())
        f += STD_HZ * self.rng.standard_normal()
        point = SweepPoint(theta0_rad, f, STD_HZ, f - P.f00_hz, STD_HZ, math.radians(2.0), 1.8, 0.5, 100.0)
        return SweepFit(cycle_id or self.cycle_id, tuning, point if ok else None, source=f"fit of {theta0_rad:.3f}")

    def run(self, runner, step, fits_first=True, ok=True):
        """Answer ``step``'s cycle; fits before the answer (as a fast estimator) or after it."""
        call = step.run_cycle
        self.cycle_id += 1
        fits = [self.fit(call.theta0_rad, ok) for _ in range(call.repeats)]
        answer = CycleAnswer(self.cycle_id, call.repeats)
        if fits_first:
            assert all(runner.on_fit(f) is None for f in fits)
            return runner.on_cycle(answer)
        assert not runner.on_cycle(answer).run_cycle  # waiting for the fits
        steps = [runner.on_fit(f) for f in fits]
        assert steps[:-1] == [None] * (len(fits) - 1)
        return steps[-1]


def started(goal=SweepGoal(ANGLES, 2), settings=SweepSettings(probes=OWN)):
    runner = SweepRunner()
    runner.start(goal, settings)
    return runner, runner.begin()


def test_a_sweep_runs_a_cycle_per_angle_and_recovers_the_field():
    runner, step = started()
    driver, feedback = StandIn(), []
    while step.decompose is None:
        assert step.run_cycle.theta0_rad == ANGLES[len(feedback)] and step.run_cycle.repeats == 2
        # Every other cycle its fits come late; other cycles' and tuning fits do not count.
        assert runner.on_fit(driver.fit(0.0, cycle_id=999)) is None
        assert runner.on_fit(driver.fit(0.0, tuning=True, cycle_id=driver.cycle_id + 1)) is None
        step = driver.run(runner, step, fits_first=len(feedback) % 2 == 0)
        feedback.append(step.feedback)
    assert [f.angle_index for f in feedback] == list(range(len(ANGLES)))
    assert all(f.n_ok == 2 and len(f.fits) == 2 and f.n_angles == len(ANGLES) for f in feedback)
    assert runner.state == "decomposing" and runner.on_fit(driver.fit(0.0)) is None
    step = runner.on_decomposed(step.decompose())
    outcome, (sweep,) = step.finished, step.publish
    assert outcome.ok and sweep is outcome.map and sweep.sweep_id == 1 and runner.state == "idle"
    d = sweep.decomposition
    sigma = np.sqrt(np.diag(d.field_covariance_t2))
    assert np.all(np.abs(d.field_t - FIELD_T[:2]) < 4 * sigma), (d.field_t, sigma)
    assert len(sweep.record.points) == 2 * len(ANGLES) and sweep.f00_hz == pytest.approx(P.f00_hz)


def test_a_goal_without_angles_or_repeats_takes_the_settings():
    runner, step = started(SweepGoal(), SweepSettings(probes=OWN, repeats_per_angle=3, angle_step_deg=72.0))
    driver, calls = StandIn(), []
    while step.run_cycle is not None:
        calls.append(step.run_cycle)
        step = driver.run(runner, step)
    assert [c.theta0_rad for c in calls] == pytest.approx(np.radians([0, 72, 144, 216, 288]))
    assert {c.repeats for c in calls} == {3}


def test_late_fits_are_given_up_on_when_their_time_is_up():
    runner, step = started(SweepGoal(ANGLES[:5], 3))
    driver = StandIn()
    assert runner.fits_time_up() is None  # no cycle answered yet: nothing is late
    driver.cycle_id += 1
    assert runner.on_fit(driver.fit(0.0)) is None
    assert not runner.on_cycle(CycleAnswer(driver.cycle_id, 3)).run_cycle
    step = runner.fits_time_up()
    assert step.feedback.n_ok == 1 and step.run_cycle.theta0_rad == ANGLES[1]


@pytest.mark.parametrize(
    "problem", ["cycle failed: coil current above the cap", "the driver's run_cycle service is not available"]
)
def test_a_failing_driver_ends_the_sweep_with_its_reason(problem):
    runner, step = started()
    step = StandIn().run(runner, step)
    step = runner.on_cycle(CycleAnswer(problem=problem))
    assert not step.finished.ok and step.finished.message == f"orientation 1 (30.0°): {problem}"
    assert step.publish == () and runner.state == "idle" and runner.sweeps == 0


def test_a_cancel_ends_the_sweep_before_the_next_orientation():
    runner, step = started()
    runner.cancel()
    step = StandIn().run(runner, step)
    assert step.feedback.angle_index == 0 and step.run_cycle is None
    assert step.finished.cancelled and not step.finished.ok
    assert step.finished.message == f"cancelled after 1 of {len(ANGLES)} orientations"
    runner.start(SweepGoal(ANGLES), SweepSettings(probes=OWN))  # free again


def test_a_sweep_without_one_good_ringdown_fails_and_publishes_nothing():
    runner, step = started(SweepGoal(ANGLES[:5], 2))
    driver = StandIn()
    while step.finished is None:
        step = driver.run(runner, step, ok=False)
    assert not step.finished.ok and step.finished.message == "no successful ring-down in the sweep (10 failed)"
    assert step.publish == () and runner.sweeps == 1


def test_a_failed_decomposition_ends_the_sweep_and_leaves_nothing_to_publish():
    runner, step = started(SweepGoal(ANGLES[:5], 1))
    driver = StandIn()
    while step.decompose is None:
        step = driver.run(runner, step)
    failed = Decomposition("first_principles", DecompositionStatus.NOT_CONVERGED, "the fit did not converge")
    step = runner.on_decomposed([failed])
    assert step.publish == () and not step.finished.ok and step.finished.message == "the fit did not converge"
    assert step.finished.map.decomposition is failed and runner.state == "idle"


@pytest.mark.parametrize(
    "goal, settings, reason",
    [
        (SweepGoal((0.0, math.nan)), SweepSettings(probes=OWN), "not all finite"),
        (
            SweepGoal(ANGLES, model="paper"),
            SweepSettings(probes=OWN),
            "'paper' is not one of first_principles, published",
        ),
        # The field is the 1θ0 harmonic and the gradient the 2θ0 one: 4 orientations cannot tell
        # them from the constant term, 5 cannot when f00 is free too.
        (SweepGoal(ANGLES[:4]), SweepSettings(probes=OWN), "4 distinct orientations .* need at least 5"),
        (SweepGoal(ANGLES[:2] * 3), SweepSettings(probes=OWN), "2 distinct orientations"),
        (SweepGoal(ANGLES[:5]), SweepSettings(probes=OWN, f00_free=True), "need at least 6"),
        (SweepGoal(), SweepSettings(probes=OWN, angle_step_deg=90.0), "4 distinct orientations"),
        (SweepGoal(ANGLES, 101), SweepSettings(probes=OWN), r"repeats_per_angle=101 is outside \[1, 100\]"),
    ],
)
def test_bad_goals_are_refused_with_the_reason_before_any_cycle(goal, settings, reason):
    runner = SweepRunner()
    with pytest.raises(ValueError, match=reason):
        runner.start(goal, settings)
    assert runner.state == "idle"


def test_five_orientations_are_enough():
    runner, step = started(SweepGoal(ANGLES[:5]))
    assert step.run_cycle is not None


def test_one_sweep_at_a_time_and_the_runner_is_freed_when_abandoned():
    runner, _ = started()
    with pytest.raises(ValueError, match="another sweep is still running"):
        runner.start(SweepGoal(ANGLES), SweepSettings(probes=OWN))
    assert not runner.abandon("the node stops").finished.ok and runner.state == "idle"
    assert runner.abandon("again").finished is None


def test_a_manual_stage_asks_the_operator_before_each_cycle():
    runner, step = started(settings=SweepSettings(probes=OWN, manual_orientation=True))
    driver, turns = StandIn(), []
    while step.decompose is None:
        assert step.run_cycle is None and step.turn == runner.turn_awaited
        turns.append(step.turn)
        assert runner.on_fit(driver.fit(step.turn)) is None  # a fit before the turn is no cycle's
        step = runner.on_turned()
        assert runner.turn_awaited is None and step.run_cycle.theta0_rad == turns[-1]
        assert step.run_cycle.turned_by_hand  # the driver hears that the operator turned it
        step = driver.run(runner, step)
    assert turns == list(ANGLES)
    assert turn_prompt(math.radians(45.0)) == "turn the probe to θ0 = 45° and confirm"
    assert runner.on_decomposed(step.decompose()).finished.ok


def test_a_sweep_cancelled_while_the_operator_turns_ends_there():
    runner, step = started(settings=SweepSettings(probes=OWN, manual_orientation=True))
    runner.cancel()
    end = runner.on_turned()
    assert end.finished.cancelled and end.run_cycle is None and runner.state == "idle"
    assert runner.on_turned() == type(end)()  # a late confirmation changes nothing


def test_a_turn_not_confirmed_in_time_fails_the_sweep_naming_the_orientation():
    runner, step = started(settings=SweepSettings(probes=OWN, manual_orientation=True))
    assert step.turn == ANGLES[0]
    end = runner.turn_timed_out(30.0)
    assert not end.finished.ok and not end.finished.cancelled and runner.state == "idle"
    assert end.finished.message == "no confirmation of θ0 = 0° within 30 s"
    assert runner.turn_timed_out(30.0) == type(end)()  # no turn awaited: nothing ends


def test_the_last_failure_stays_until_a_sweep_succeeds_and_a_cancel_leaves_it():
    runner, goal = SweepRunner(), SweepGoal(ANGLES[:5], 1)
    assert runner.last_failure == ""
    runner.start(goal, SweepSettings(probes=OWN))
    runner.begin()
    runner.abandon("the driver left")
    assert runner.last_failure == "the driver left"
    runner.start(goal, SweepSettings(probes=OWN))
    step = runner.begin()
    runner.cancel()
    assert StandIn().run(runner, step).finished.cancelled and runner.last_failure == "the driver left"
    runner.start(goal, SweepSettings(probes=OWN))
    step, driver = runner.begin(), StandIn()
    while step.decompose is None:
        step = driver.run(runner, step)
    assert runner.on_decomposed(step.decompose()).finished.ok and runner.last_failure == ""


def test_a_cancel_that_stops_the_running_cycle_ends_the_sweep_cancelled_not_failed():
    """The client cancels while a cycle runs: the mapper cancels that cycle, whose answer then
    says so. That answer is the cancel taking effect, not a failure: CANCELED, and the last
    failure (the mapper's WARN on /diagnostics) untouched."""
    runner, step = started()
    assert step.run_cycle is not None
    runner.cancel()
    step = runner.on_cycle(CycleAnswer(problem="cycle failed: cancelled: its goal was cancelled"))
    assert step.finished.cancelled and not step.finished.ok
    assert step.finished.message == "cancelled during orientation 0 (0.0°)"
    assert runner.last_failure == ""


def test_a_cancel_during_the_last_orientation_ends_the_sweep_without_a_map():
    """A cancel that comes while the last cycle's fits are awaited (the cycle itself had ended)
    must not let the sweep run on to a map nobody waits for."""
    runner, step = started(SweepGoal(ANGLES[:5], 1))
    driver = StandIn()
    for _ in range(4):
        step = driver.run(runner, step)
    driver.cycle_id += 1
    assert not runner.on_cycle(CycleAnswer(driver.cycle_id, 1)).run_cycle  # its fit is awaited
    runner.cancel()
    step = runner.on_fit(driver.fit(step.run_cycle.theta0_rad))
    assert step.decompose is None and step.publish == ()
    assert step.finished.cancelled and step.finished.message == "cancelled after 5 of 5 orientations"
    assert runner.cancels == 1 and runner.last_cancel == step.finished.message and runner.state == "idle"


def test_a_cancel_during_the_decomposition_publishes_nothing():
    runner, step = started(SweepGoal(ANGLES[:5], 1))
    driver = StandIn()
    while step.decompose is None:
        step = driver.run(runner, step)
    runner.cancel()  # the decomposition is under way in a worker thread
    step = runner.on_decomposed(step.decompose())
    assert step.publish == () and step.finished.cancelled and not step.finished.ok
    assert step.finished.message == "cancelled while decomposing 5 orientations"
    assert runner.state == "idle" and runner.last_failure == ""


def test_a_map_names_the_cycles_of_its_sweep():
    runner, step = started(SweepGoal(ANGLES[:5], 1))
    driver = StandIn()
    driver.cycle_id = 40  # cycles run before the sweep are not its
    while step.decompose is None:
        step = driver.run(runner, step)
    (sweep,) = runner.on_decomposed(step.decompose()).publish
    assert sweep.cycle_ids == (41, 42, 43, 44, 45)


def test_the_settings_carry_their_probes_one_probe_a_set_of_one():
    # The runner takes the sweep's probes from its settings alone: there is no other probe to fall back on.
    with pytest.raises(TypeError, match="probes"):
        SweepSettings()  # type: ignore[call-arg]
    with pytest.raises(ValueError, match="one probe is a set of one"):
        SweepSettings(probes=())
    runner, _ = started()
    assert runner.settings.probes == OWN
