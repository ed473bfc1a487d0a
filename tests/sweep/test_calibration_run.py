"""The calibrator's goals without ROS (mows.sweep.calibration.run): a goal's plan, fits routed to
the cycle that made them, the supply back at zero in every ending, and a whole calibration
through a stand-in driver whose ring-downs come from the exact field of the calibration bench."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mows.device.cycle.phases import CycleRequest
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitStatus, RingdownFit
from mows.physics.probe import PAPER_PROBE, Probe, calibration_record
from mows.sweep.calibration.run import Bench, CalibrationRun, ProbeCalibrator, Turn, goal_plan
from mows.sweep.calibration.schedule import CalibrationPlan, SetSupply, scenario_wirings
from mows.sweep.events import CycleAnswer
from sweep.calibration_bench import BENCH, STD_HZ, bench_fits


def goal(currents_a=(), theta0_rad=(), repeats=0, wiring=""):
    """A CalibrateProbe goal as the node gets it."""
    return SimpleNamespace(currents_a=currents_a, theta0_rad=theta0_rad, repeats=repeats, wiring=wiring)


def ok_fit(**fields):
    """An OK fit: a ring-down at 112.5 Hz and θ0 = 0 unless ``fields`` say otherwise."""
    typical = dict(theta0_rad=0.0, frequency_hz=112.5, frequency_std_hz=STD_HZ, amplitude_rad=0.41, duration_s=0.5)
    return RingdownFit(FitStatus.OK, start_offset_s=COIL_OFF_SKIP_S, **(typical | dict(damping_per_s=1.8) | fields))


class StandInDriver:
    """Answers SetSupply and CycleRequest as the driver would, with the bench's ring-downs."""

    def __init__(self):
        self.current_a, self.cycle_id, self.currents = 0.0, 0, []
        self.rng = np.random.default_rng(3)

    def supply(self, action: SetSupply) -> None:
        self.current_a = action.current_a
        self.currents.append(action.current_a)

    def cycle(self, action: CycleRequest) -> tuple[CycleAnswer, list]:
        self.cycle_id += 1
        fits = [ok_fit(**f) for f in bench_fits(self.current_a, action.theta0_rad, action.repeats, self.rng)]
        return CycleAnswer(self.cycle_id, action.repeats), fits


def run_through(run: CalibrationRun, driver: StandInDriver, fits_first=False, cancel_at=None):
    """Walks the run to its outcome, the fits delivered before or after the driver's answer."""
    step, steps = run.start(), 0
    while step.outcome is None:
        steps += 1
        if steps == cancel_at:
            step = run.cancel("cancelled by the client") or step
        (action,) = step.actions
        if isinstance(action, SetSupply):
            driver.supply(action)
            step = run.on_supply(True)
            continue
        answer, fits = driver.cycle(action)
        delivered = [run.on_fit(answer.cycle_id, fit) for fit in fits] if fits_first else []
        answered = run.on_cycle(answer)
        if not fits_first:
            delivered = [run.on_fit(answer.cycle_id, fit) for fit in fits]
        (step,) = [s for s in [*delivered, answered] if s is not None]  # exactly one step: when all are in
    return step.outcome


def test_a_goal_leaves_to_the_defaults_what_it_does_not_say():
    plan = goal_plan(goal(), "helmholtz", (0.0, 1.0))
    assert plan == CalibrationPlan((0.0, 1.0), (0.0, math.pi), 1, "helmholtz")
    plan = goal_plan(goal([2.0], [0.5], 3, "gradient"), "helmholtz", (0.0, 1.0))
    assert plan == CalibrationPlan((2.0,), (0.5,), 3, "gradient")
    with pytest.raises(ValueError, match="sideways"):
        goal_plan(goal(wiring="sideways"), "helmholtz", (0.0,))
    with pytest.raises(ValueError, match="finite"):
        goal_plan(goal(currents_a=[math.nan]), "helmholtz", (0.0,))


@pytest.mark.parametrize("fits_first", [False, True])
def test_a_calibration_recovers_the_bench_probe(fits_first):
    calibrator, driver = ProbeCalibrator(), StandInDriver()
    currents = (0.0, 1.0, 2.0, -1.0, -2.0)
    run = calibrator.accept(goal_plan(goal(currents), BENCH.supply.name, ()))
    outcome = run_through(run, driver, fits_first)
    assert outcome.success and outcome.supply_at_zero, outcome.message
    # Up at the first orientation, down at the second (no ramp at the turn), then zero.
    assert driver.currents == [*currents, *reversed(currents[:-1]), 0.0]
    assert len(outcome.points) == 2 * len(currents) and not outcome.failed
    calibrator.keep(outcome)
    # The nominal probe gives only what a calibration takes as known: the moment, the magnet's
    # mass and the housing stop.
    calibration = calibrator.calibrate(scenario_wirings(BENCH), BENCH.supply.name, PAPER_PROBE)
    probe = calibration.probe()
    assert probe.spring_nm_per_rad == pytest.approx(BENCH.probe.spring_nm_per_rad, rel=0.01)
    assert probe.inertia_kgm2 == pytest.approx(BENCH.probe.inertia_kgm2, rel=0.01)
    assert calibrator.calibrated(calibration, "probe.yaml").startswith("calibration 1: ")
    assert calibrator.calibrations == 1


def test_the_probe_file_is_what_the_estimator_loads_and_never_the_nominal_one(tmp_path):
    nominal_file = tmp_path / "nominal.yaml"
    PAPER_PROBE.to_yaml(nominal_file)
    bench = Bench(scenario_wirings(BENCH), BENCH.supply.name, PAPER_PROBE, "bench-3", str(nominal_file))
    calibrator, path = ProbeCalibrator(), tmp_path / "probe.yaml"
    outcome = run_through(calibrator.accept(goal_plan(goal((0.0, 1.0, 2.0)), BENCH.supply.name, ())), StandInDriver())
    calibrator.keep(outcome)
    calibration, written = calibrator.write_probe(bench, str(path), "2026-01-02T03:04:05+00:00")
    assert written == f"wrote {path}" and calibrator.calibrations == 1 and str(path) in calibrator.last
    assert Probe.from_yaml(path).spring_nm_per_rad == pytest.approx(BENCH.probe.spring_nm_per_rad, rel=0.01)
    record = calibration_record(path)
    assert (record["date"], record["hardware_id"]) == ("2026-01-02T03:04:05+00:00", "bench-3")
    assert record["constants"]["f00_hz"]["value"] == pytest.approx(calibration.value("f00_hz"))
    # A later goal replaces it, but not the nominal probe file the calibration reads.
    assert calibrator.write_probe(bench, str(path))[1] == f"replaced {path}"
    nominal_text = nominal_file.read_text()
    with pytest.raises(ValueError, match="is an input"):
        calibrator.write_probe(bench, str(nominal_file))
    assert nominal_file.read_text() == nominal_text and calibrator.calibrations == 2


def test_a_driver_without_a_supply_or_with_too_small_a_range_frees_the_calibrator():
    calibrator = ProbeCalibrator()
    calibrator.accept(CalibrationPlan((0.0, -1.0)))
    assert (
        calibrator.on_zero_supply(False, "no supply", math.nan, math.nan)
        == "the driver's supply cannot be set: no supply"
    )
    assert calibrator.run is None
    calibrator.accept(CalibrationPlan((0.0, -1.0)))
    assert calibrator.on_zero_supply(True, "", 0.0, 2.0).startswith("supply current -1 A of the plan is outside")
    assert calibrator.run is None
    run = calibrator.accept(CalibrationPlan((0.0, -1.0)))
    assert calibrator.on_zero_supply(True, "", -2.0, 2.0) is None and calibrator.run is run
    calibrator.release()
    calibrator.accept(CalibrationPlan((0.0, -1.0)))
    assert calibrator.on_zero_supply(True, "", math.nan, math.nan) is None  # no range stated: the device refuses


def test_a_goal_takes_the_fits_of_its_probe_and_counts_the_others():
    calibrator = ProbeCalibrator()
    calibrator.accept(CalibrationPlan(), probe_id=1)
    assert [calibrator.calibrates(i) for i in (0, 1, 2, 1)] == [False, True, False, True]
    assert calibrator.others == 2
    calibrator.release()
    calibrator.accept(CalibrationPlan())
    assert calibrator.others == 0 and calibrator.calibrates(0)


def test_fits_of_other_cycles_and_late_fits_are_told_apart():
    run = CalibrationRun(CalibrationPlan((0.0,), (0.0,), repeats=2))
    assert isinstance(run.start().actions[0], SetSupply)
    (cycle,) = run.on_supply(True).actions
    assert isinstance(cycle, CycleRequest) and cycle.repeats == 2
    assert run.on_fit(6, ok_fit()) is None  # another client's cycle
    assert run.on_cycle(CycleAnswer(7, 2)) is None  # its fits are due
    assert run.on_fit(6, ok_fit()) is None
    assert run.on_fit(7, ok_fit()) is None  # one of two
    step = run.fits_time_up()  # the second never comes
    assert step.actions == [SetSupply(0.0)]
    outcome = run.on_supply(True).outcome
    assert outcome.success and len(outcome.points) == 1 and outcome.failed == {(0.0, "NO_FIT"): 1}


def test_a_failed_cycle_and_a_cancel_end_with_the_supply_at_zero():
    run = CalibrationRun(CalibrationPlan((1.0,), (0.0,)))
    run.start()
    run.on_supply(True)
    step = run.on_cycle(CycleAnswer(problem="coil current above the cap"))
    assert step.actions == [SetSupply(0.0)]
    assert run.cancel("too late") is None  # already on its way to zero: its step stands
    outcome = run.on_supply(True).outcome
    assert not outcome.success and not outcome.cancelled and "coil current above the cap" in outcome.message

    driver = StandInDriver()
    outcome = run_through(CalibrationRun(CalibrationPlan((0.0, 1.0, 2.0))), driver, cancel_at=3)
    assert outcome.cancelled and outcome.supply_at_zero and driver.currents == [0.0, 0.0]


def test_one_goal_at_a_time_and_no_constants_without_a_homogeneous_sweep():
    calibrator = ProbeCalibrator()
    assert calibrator.state == "idle"
    run = calibrator.accept(CalibrationPlan((0.0, 1.0), wiring="gradient"))
    assert calibrator.state == "calibrating"
    with pytest.raises(ValueError, match="running"):
        calibrator.accept(CalibrationPlan())
    outcome = run_through(run, StandInDriver())
    calibrator.keep(outcome)
    calibrator.release()
    with pytest.raises(ValueError, match="homogeneous"):
        calibrator.calibrate(scenario_wirings(BENCH), BENCH.supply.name, PAPER_PROBE)
    assert calibrator.accept(CalibrationPlan()) is calibrator.run


def test_a_manual_stage_is_turned_once_per_orientation():
    plan = CalibrationPlan((0.0, 1.0), (0.0, math.pi), 1)
    run = CalibrationRun(plan, manual_orientation=True)
    driver, turns, prompts = StandInDriver(), [], []
    step = run.start()
    while step.outcome is None:
        prompts += [f.message for f in step.feedback if f.message.startswith("turn")]
        (action,) = step.actions
        if isinstance(action, SetSupply):
            driver.supply(action)
            step = run.on_supply(True)
        elif isinstance(action, Turn):
            assert run.turn_awaited == action.theta0_rad
            turns.append(action.theta0_rad)
            step = run.on_turned()
            assert run.turn_awaited is None and step.actions == [
                CycleRequest(action.theta0_rad, 1, turned_by_hand=True)
            ]
        else:
            assert action.turned_by_hand  # every cycle on this stage was turned by the operator
            answer, fits = driver.cycle(action)
            assert [run.on_fit(answer.cycle_id, fit) for fit in fits] == [None]
            step = run.on_cycle(answer)
    assert step.outcome.success and len(step.outcome.points) == plan.steps
    # Every current at 0°, then every current at 180°: one turn per orientation.
    assert turns == [0.0, math.pi]
    assert prompts == ["turn the probe to θ0 = 0° and confirm", "turn the probe to θ0 = 180° and confirm"]


def test_a_cancel_while_the_operator_turns_ramps_the_supply_down():
    run = CalibrationRun(CalibrationPlan((1.0,), (0.5,), 1), manual_orientation=True)
    run.start()
    (turn,) = run.on_supply(True).actions
    assert turn == Turn(0.5)
    (action,) = run.cancel("cancelled by the client").actions
    assert action == SetSupply(0.0) and run.turn_awaited is None and run.on_turned().actions == []
