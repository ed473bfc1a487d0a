"""The calibration schedule (I/O-free): supply steps × orientations × cycles, and the supply back
at zero in every ending: done, cancelled, refused, failed."""

import math

import pytest

from mows.device.cycle.phases import CycleRequest
from mows.estimate.ringdown import FitStatus, RingdownFit
from mows.physics.supply import SupplyLimits
from mows.sweep.calibration.schedule import (
    PAPER_CURRENTS_A,
    CalibrationPlan,
    CalibrationSchedule,
    SetSupply,
    State,
    default_currents_a,
)

PLAN = CalibrationPlan(currents_a=(0.0, 1.0, -1.0), theta0_rad=(0.0, math.pi), repeats=2)


def fit(ok=True, frequency_hz=112.5):
    if not ok:
        return RingdownFit(status=FitStatus.SATURATED, message="clipped")
    return RingdownFit(
        status=FitStatus.OK,
        theta0_rad=0.0,
        frequency_hz=frequency_hz,
        frequency_std_hz=3e-4,
        damping_per_s=1.8,
        amplitude_rad=0.41,
        duration_s=0.5,
        start_offset_s=0.003,
    )


def run_until_end(schedule, step, fits_per_cycle=None, refuse=None):
    """Answer every action as a device would; returns the actions seen and the outcome."""
    seen = []
    pending = [step]
    while pending:
        step = pending.pop(0)
        if step.outcome is not None:
            return seen, step.outcome
        for action in step.actions:
            seen.append(action)
            if isinstance(action, SetSupply):
                refused = refuse is not None and action.current_a == refuse
                pending.append(schedule.on_supply(not refused, "over the cap" if refused else ""))
            else:
                for k in range(action.repeats if fits_per_cycle is None else fits_per_cycle):
                    pending.append(schedule.on_fit(fit(ok=k == 0 or schedule.current_a != -1.0)))
                pending.append(schedule.on_cycle_done(True))
    raise AssertionError("no outcome")


def test_the_plan_is_walked_orientation_by_orientation_and_ends_at_zero():
    schedule = CalibrationSchedule(PLAN)
    seen, outcome = run_until_end(schedule, schedule.start())
    supplies = [a.current_a for a in seen if isinstance(a, SetSupply)]
    cycles = [a for a in seen if isinstance(a, CycleRequest)]
    # The currents up at 0°, down at 180° (no ramp at the turn), then back to zero.
    assert supplies == [0.0, 1.0, -1.0, 1.0, 0.0, 0.0]
    assert [c.theta0_rad for c in cycles] == [0.0] * 3 + [math.pi] * 3 and all(c.repeats == 2 for c in cycles)
    assert outcome.success and outcome.supply_at_zero and not outcome.cancelled
    assert len(outcome.points) == 10  # 12 ring-downs, 2 saturated at −1 A
    assert outcome.failed == {(-1.0, "SATURATED"): 2}
    assert {p.supply_current_a for p in outcome.points} == {0.0, 1.0, -1.0}
    assert schedule.finished
    with pytest.raises(ValueError):
        schedule.start()


def test_feedback_counts_the_steps_and_the_ring_downs():
    schedule = CalibrationSchedule(PLAN)
    first = schedule.start()
    assert first.feedback[0].step == 1 and first.feedback[0].steps == 6
    step = schedule.on_supply(True)
    schedule.on_fit(fit())
    schedule.on_fit(fit())
    step = schedule.on_cycle_done(True)
    assert step.actions == [SetSupply(1.0)]  # the next current at the same orientation
    assert step.feedback[0].step == 2 and step.feedback[0].ringdowns == 2
    schedule.on_supply(True)
    for current_a in (1.0, -1.0):
        schedule.on_fit(fit())
        schedule.on_fit(fit())
        step = schedule.on_cycle_done(True)
        if current_a == 1.0:
            schedule.on_supply(True)
    assert step.actions == [CycleRequest(math.pi, 2)]  # the turn, at the current already set
    assert step.feedback[0].step == 4 and step.feedback[0].ringdowns == 6


def test_cancel_mid_cycle_ramps_to_zero_before_it_reports_and_ignores_late_fits():
    schedule = CalibrationSchedule(PLAN)
    schedule.start()
    schedule.on_supply(True)
    schedule.on_fit(fit())
    step = schedule.cancel("user")
    assert step.actions == [SetSupply(0.0)] and step.outcome is None and schedule.state == State.RETURNING
    assert schedule.on_fit(fit()).actions == [] and schedule.on_cycle_done(True).actions == []
    assert schedule.cancel("again").actions == []
    outcome = schedule.on_supply(True).outcome
    assert outcome.cancelled and not outcome.success and outcome.supply_at_zero and len(outcome.points) == 1


def test_a_refused_current_or_a_failed_cycle_also_ends_at_zero():
    schedule = CalibrationSchedule(PLAN)
    seen, outcome = run_until_end(schedule, schedule.start(), refuse=1.0)
    assert [a.current_a for a in seen if isinstance(a, SetSupply)] == [0.0, 1.0, 0.0]
    assert not outcome.success and "refused" in outcome.message and outcome.supply_at_zero

    schedule = CalibrationSchedule(PLAN)
    schedule.start()
    schedule.on_supply(True)
    step = schedule.on_cycle_done(False, "link lost")
    assert step.actions == [SetSupply(0.0)]
    outcome = schedule.on_supply(True).outcome
    assert not outcome.success and "link lost" in outcome.message


def test_an_unconfirmed_zero_is_reported_as_such():
    schedule = CalibrationSchedule(PLAN)
    schedule.start()
    schedule.cancel()
    outcome = schedule.on_supply(False, "link down").outcome
    assert not outcome.supply_at_zero and "DID NOT CONFIRM ZERO" in outcome.message


def test_fits_that_come_after_the_cycle_are_waited_for_and_a_timeout_goes_on_without_them():
    schedule = CalibrationSchedule(CalibrationPlan(currents_a=(0.0, 1.0), theta0_rad=(0.0,), repeats=2))
    schedule.start()
    schedule.on_supply(True)
    assert schedule.on_cycle_done(True).actions == [] and schedule.state == State.AWAITING_FITS
    schedule.on_fit(fit())
    assert schedule.on_fit(fit()).actions == [SetSupply(1.0)]
    schedule.on_supply(True)
    schedule.on_fit(fit())
    schedule.on_cycle_done(True)
    step = schedule.fits_timed_out()
    assert step.actions == [SetSupply(0.0)]
    outcome = schedule.on_supply(True).outcome
    assert outcome.success and len(outcome.points) == 3 and outcome.failed == {(1.0, "NO_FIT"): 1}


def test_a_plan_without_currents_or_with_bad_values_is_refused():
    for bad in (dict(currents_a=()), dict(currents_a=(math.nan,)), dict(theta0_rad=()), dict(repeats=0)):
        with pytest.raises(ValueError):
            CalibrationPlan(**bad)


def test_a_unipolar_supply_gets_the_non_negative_plan_and_refuses_the_paper_plan_up_front():
    unipolar, bipolar = SupplyLimits(polarity="unipolar"), SupplyLimits()
    assert default_currents_a(bipolar) == PAPER_CURRENTS_A
    assert default_currents_a(unipolar) == (0.0, 0.5, 1.0, 1.5, 2.0)
    CalibrationPlan(default_currents_a(unipolar)).check_supply(unipolar.min_current_a, unipolar.cap_a)
    CalibrationPlan(PAPER_CURRENTS_A).check_supply(bipolar.min_current_a, bipolar.cap_a)
    CalibrationPlan(PAPER_CURRENTS_A).check_supply(math.nan, math.nan)  # a range not known: the device decides
    with pytest.raises(ValueError, match=r"-0\.5 A of the plan is outside the supply's range 0 … \+2 A"):
        CalibrationPlan(PAPER_CURRENTS_A).check_supply(unipolar.min_current_a, unipolar.cap_a)
    with pytest.raises(ValueError, match=r"\+2 A of the plan is outside the supply's range -1 … \+1 A$"):
        CalibrationPlan((0.0, 2.0)).check_supply(-1.0, 1.0)
