"""Sweeps and calibrations on a driver session without ROS: the core's I/O-free state machines
(:class:`mows.sweep.runner.SweepRunner`, :class:`mows.sweep.calibration.run.CalibrationRun`) fed
as the mapper and the calibrator feed them, the ring-downs cut from the stream and fitted as the
estimator does. ``turn`` is the operator: on a bench without a motor it turns the stage before a
cycle is asked for (the sim backend's stage turns itself, ``turn`` does nothing)."""

import dataclasses
from collections.abc import Callable

from mows.device.cycle.phases import CycleRequest, Phase
from mows.estimate.probe_set import ProbeEntry, own_probe_entry
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions
from mows.estimate.segments import RingdownWindow, SegmentAssembler, fit_segment
from mows.sweep.calibration.run import CalibrationRun, Turn
from mows.sweep.events import CycleAnswer, SweepFit, SweepGoal, SweepSettings
from mows.sweep.record import SweepPoint
from mows.sweep.runner import SweepRunner

MAX_STEPS = 200_000  # bound for a run that never ends (a bug), not a timing


@dataclasses.dataclass
class BenchRig:
    session: object
    scenario: object  # lends the probe and the fluxgate pair to the fits
    turn: Callable[[float], None] = lambda theta0_rad: None
    manual: bool = False  # the sweep asks the operator to turn the stage (orientation: manual)

    def __post_init__(self):
        self.assembler = SegmentAssembler(5.0)

    def cycle(self, theta0_rad: float, repeats: int, turned: bool = False) -> tuple[CycleAnswer, list]:
        """One cycle's answer and its measurement fits (RingdownFit), as the estimator makes them;
        the operator turns the stage first unless it is ``turned``."""
        if not turned:
            self.turn(theta0_rad)
        done, fits = [], []
        self.session.start_cycle(CycleRequest(theta0_rad, repeats=repeats, turned_by_hand=self.manual), done.append)
        for _ in range(MAX_STEPS):
            fits += self._step()
            if done and len(fits) >= done[0].ringdowns_recorded:
                outcome = done[0]
                problem = "" if outcome.success else outcome.message or "failed"
                return CycleAnswer(outcome.cycle_id, outcome.ringdowns_recorded, problem), fits
        raise AssertionError("the cycle did not end")

    def _step(self) -> list:
        output = self.session.step(0.0)
        segments = []
        for block in output.blocks:
            segments += self.assembler.add_block(block)
        for e in output.events:
            if e.phase == Phase.RINGDOWN and not e.tuning:
                window = RingdownWindow(
                    e.stamp_ns, e.planned_duration_s, e.cycle_id, e.repeat_index, e.theta0_rad, e.frequency_hz
                )
                segments += self.assembler.announce(window)
        probe, pair = self.scenario.probe, self.scenario.sensors.pair
        own, options = ProbeEntry(0, probe, probe.f00_hz), FitOptions(theta_stop_rad=probe.theta_stop_rad)
        return [
            fit_segment(
                s,
                [own.line(s.window.theta0_rad, pair, "difference", s.window.excitation_frequency_hz)],
                COIL_OFF_SKIP_S,
                options,
            )[0]
            for s in segments
        ]

    def supply(self, current_a: float):
        """Ramp the supply through the session; the device's result once the samples reached it."""
        done = []
        self.session.set_field_current(current_a, done.append)
        for _ in range(MAX_STEPS):
            if done:
                return done[0]
            self._step()
        raise AssertionError("the supply ramp did not end")

    def sweep(self, angles_rad, repeats: int):
        """A rotation sweep through the core's runner; its outcome (with the decomposition)."""
        runner = SweepRunner()
        probe = self.scenario.probe
        settings = SweepSettings(manual_orientation=self.manual, probes=(own_probe_entry(probe),))
        runner.start(SweepGoal(tuple(angles_rad), repeats), settings)
        step = runner.begin()
        while step.finished is None:
            if step.turn is not None:
                self.turn(step.turn)
                step = runner.on_turned()
                continue
            if step.decompose is not None:
                step = runner.on_decomposed(step.decompose())
                continue
            assert step.run_cycle is not None, "the runner waits for fits that the cycle said it made"
            answer, fits = self.cycle(step.run_cycle.theta0_rad, step.run_cycle.repeats, turned=self.manual)
            for fit in fits:
                point = (
                    SweepPoint.from_fit(fit, fit.frequency_hz - probe.f00_hz, fit.frequency_std_hz) if fit.ok else None
                )
                runner.on_fit(SweepFit(answer.cycle_id, False, point))
            step = runner.on_cycle(answer)
        return step.finished

    def calibrate(self, plan):
        """A calibration schedule through :class:`CalibrationRun`; its outcome."""
        run = CalibrationRun(plan, manual_orientation=self.manual)
        pending = [run.start()]
        while pending:
            step = pending.pop(0)
            if step is None:
                continue
            if step.outcome is not None:
                return step.outcome
            for action in step.actions:
                if isinstance(action, Turn):
                    self.turn(action.theta0_rad)
                    pending.append(run.on_turned())
                elif hasattr(action, "current_a"):
                    result = self.supply(action.current_a)
                    pending.append(run.on_supply(result.accepted, result.reason))
                else:
                    answer, fits = self.cycle(action.theta0_rad, action.repeats, turned=self.manual)
                    pending += [run.on_fit(answer.cycle_id, fit) for fit in fits]
                    pending.append(run.on_cycle(answer))
        raise AssertionError("the calibration ended without an outcome")
