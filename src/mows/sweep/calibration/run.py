"""The calibrator's goals as I/O-free classes around :class:`CalibrationSchedule` (paper Fig. 3),
in the manner of :class:`mows.device.cycle.sequencer.CycleSequencer`: fed the driver's answers, the
ring-down fits of the stream and the client's cancel, they return the schedule's steps.

:class:`CalibrationRun` runs one goal: it routes each fit to the cycle that made it (by cycle
id), waits until a finished cycle's fits are in (or the caller says their time is up), and only
then hands them to the schedule. :class:`ProbeCalibrator` takes one goal at a time, keeps each
wiring's last complete sweep across goals (a gradient sweep of an earlier goal adds the lever
check to a later homogeneous one) and fits the probe's constants from them
(:func:`mows.estimate.calibration.fit_constants.calibrate_probe`) and writes the probe file.
Reading scenarios and the driver's answers are the caller's business.
"""

import dataclasses
import datetime
import enum
import math

from mows.device.cycle.phases import CycleRequest
from mows.estimate.calibration.constants import KnownConstants, ProbeCalibration
from mows.estimate.calibration.fit_constants import calibrate_probe
from mows.physics.probe import Probe
from mows.sweep.calibration.schedule import (
    GRADIENT_WIRING,
    CalibrationOutcome,
    CalibrationPlan,
    CalibrationSchedule,
    CalibrationStep,
)
from mows.sweep.events import CycleAnswer
from mows.sweep.operator import turn_prompt


@dataclasses.dataclass(frozen=True)
class Turn:
    """Ask the operator to turn the stage to ``theta0_rad`` (a stage without a motor); answer with
    :meth:`CalibrationRun.on_turned` once they confirm."""

    theta0_rad: float


def goal_plan(goal, homogeneous: str, default_currents_a) -> CalibrationPlan:
    """The plan a goal (``currents_a``, ``theta0_rad``, ``repeats``, ``wiring``: a CalibrateProbe
    goal) asks for: no currents take ``default_currents_a``, no angles 0° and 180°, 0 repeats
    one; wiring '' is the ``homogeneous`` one. ValueError for any other wiring than those two,
    or a plan :class:`CalibrationPlan` refuses."""
    if goal.wiring and goal.wiring != GRADIENT_WIRING:
        raise ValueError(f"wiring {goal.wiring!r}: '' (homogeneous) or {GRADIENT_WIRING!r}")
    return CalibrationPlan(
        tuple(goal.currents_a) or tuple(default_currents_a),
        tuple(goal.theta0_rad) or (0.0, math.pi),
        int(goal.repeats) or 1,
        goal.wiring or homogeneous,
    )


class CalibrationRun:
    """One goal's schedule (module docstring): pass :meth:`start`'s step on, then answer each
    step's action with :meth:`on_supply`, :meth:`on_cycle` or (``manual_orientation``: a stage the
    operator turns) :meth:`on_turned`; a None from :meth:`on_cycle` or :meth:`on_fit` means the
    cycle's fits are still due."""

    def __init__(self, plan: CalibrationPlan, manual_orientation: bool = False):
        self.plan = plan
        self.schedule = CalibrationSchedule(plan)
        self.manual_orientation = manual_orientation
        self._fits: dict[int, list] = {}  # cycle id → its fits so far
        self._awaited: CycleAnswer | None = None  # the finished cycle whose fits are due
        self._stage_rad = math.nan  # where the operator last confirmed the stage
        self._turning: CalibrationStep | None = None  # the cycle's step that waits for the operator's turn

    @property
    def turn_awaited(self) -> float | None:
        """The orientation (rad) the operator has been asked to turn the stage to, if any."""
        return None if self._turning is None else self._turning.actions[0].theta0_rad

    def start(self) -> CalibrationStep:
        return self.schedule.start()

    def on_supply(self, accepted: bool, reason: str = "") -> CalibrationStep:
        return self._gate(self.schedule.on_supply(accepted, reason))

    def on_turned(self) -> CalibrationStep:
        """The operator confirmed the turn: the cycle that waited for it."""
        step, self._turning = self._turning, None
        if step is None:
            return CalibrationStep()
        self._stage_rad = step.actions[0].theta0_rad
        return CalibrationStep(actions=step.actions)

    def _gate(self, step: CalibrationStep) -> CalibrationStep:
        """With a manual stage, a cycle at another orientation than the stage's waits for a turn,
        and every cycle says the stage was turned by hand."""
        if not self.manual_orientation:
            return step
        by_hand = [
            dataclasses.replace(a, turned_by_hand=True) if isinstance(a, CycleRequest) else a for a in step.actions
        ]
        step = dataclasses.replace(step, actions=by_hand)
        cycles = [a for a in step.actions if isinstance(a, CycleRequest)]
        if not cycles or cycles[0].theta0_rad == self._stage_rad:
            return step
        self._turning = step
        # The schedule words every cycle's step (its feedback); the prompt is that, reworded.
        prompt = dataclasses.replace(step.feedback[-1], message=turn_prompt(cycles[0].theta0_rad))
        return CalibrationStep(actions=[Turn(cycles[0].theta0_rad)], feedback=[*step.feedback, prompt])

    def on_cycle(self, answer: CycleAnswer) -> CalibrationStep | None:
        """The driver's answer to the step's ``CycleRequest``; None while that cycle's fits are due."""
        if answer.problem:
            return self.schedule.on_cycle_done(False, answer.problem)
        self._awaited = answer
        return self._collected(late=False)

    def on_fit(self, cycle_id: int, fit) -> CalibrationStep | None:
        """A fit of the stream (``RingdownFit``; tuning fits are not passed); a step once the
        awaited cycle's fits are all in. Fits may come before the driver's answer."""
        self._fits.setdefault(cycle_id, []).append(fit)
        return self._collected(late=False)

    def fits_time_up(self) -> CalibrationStep | None:
        """The awaited cycle's fits are late: go on with those that came."""
        return self._collected(late=True)

    def cancel(self, reason: str) -> CalibrationStep | None:
        """The supply's way to zero; None when the schedule is on it already (its step stands)."""
        self._turning = None
        step = self.schedule.cancel(reason)
        return step if step.actions else None

    def _collected(self, late: bool) -> CalibrationStep | None:
        answer = self._awaited
        if answer is None or (not late and len(self._fits.get(answer.cycle_id, ())) < answer.ringdowns_recorded):
            return None
        self._awaited = None
        for fit in self._fits.pop(answer.cycle_id, [])[: self.plan.repeats]:
            self.schedule.on_fit(fit)
        step = self.schedule.on_cycle_done(True)
        return self._gate(step if step.actions or step.outcome else self.schedule.fits_timed_out())


@dataclasses.dataclass(frozen=True)
class Bench:
    """The calibration bench: the supply's wirings by name (:class:`Wiring`; ``homogeneous`` the
    one that gives β0), the nominal probe (read from ``nominal_file``, '' none) and the hardware
    id for the probe file."""

    wirings: dict
    homogeneous: str
    nominal: Probe
    hardware_id: str
    nominal_file: str = ""


class CalibratorState(enum.StrEnum):
    """Whether :class:`ProbeCalibrator` runs a goal; the values are what /diagnostics shows."""

    IDLE = "idle"
    CALIBRATING = "calibrating"


class ProbeCalibrator:
    """One goal at a time (``run`` while it lasts), the sweeps by wiring, the calibrations made."""

    def __init__(self) -> None:
        self.run: CalibrationRun | None = None
        self.probe_id, self.others = 0, 0  # the running goal's probe; fits of other probes left out
        self.calibrations = 0
        self.last = "no calibration yet"
        self._sweeps: dict[str, tuple] = {}  # wiring → (points, failed) of its last complete sweep

    @property
    def turn_awaited(self) -> float | None:
        """The orientation (rad) the running goal has asked the operator to turn the stage to, if any."""
        return None if self.run is None else self.run.turn_awaited

    @property
    def state(self) -> CalibratorState:
        return CalibratorState.IDLE if self.run is None else CalibratorState.CALIBRATING

    def accept(self, plan: CalibrationPlan, manual_orientation: bool = False, probe_id: int = 0) -> CalibrationRun:
        """The goal's run (on a stage the operator turns with ``manual_orientation``) of the probe
        ``probe_id`` (of several sharing each window); ValueError while another one runs."""
        if self.run is not None:
            raise ValueError("a calibration is running")
        self.run = CalibrationRun(plan, manual_orientation)
        self.probe_id, self.others = probe_id, 0
        return self.run

    def calibrates(self, probe_id: int) -> bool:
        """Whether a fit of ``probe_id`` is of the goal's probe; those of others are counted."""
        if probe_id != self.probe_id:
            self.others += 1
        return probe_id == self.probe_id

    def on_zero_supply(self, accepted: bool, reason: str, min_current_a: float, max_current_a: float) -> str | None:
        """The driver's answer to the supply set to zero before the run (a driver that cannot
        has no supply to calibrate with) and the supply's range it states, which the plan must
        lie in before any other current is set: None when the run goes on, else why not (the
        goal is released)."""
        assert self.run is not None  # only an accepted goal's supply is set
        try:
            if not accepted:
                raise ValueError(f"the driver's supply cannot be set: {reason}")
            self.run.plan.check_supply(min_current_a, max_current_a)
        except ValueError as error:
            self.release()
            return str(error)
        return None

    def release(self) -> None:
        """The goal ended (however it did): the next one may come."""
        self.run = None

    def keep(self, outcome: CalibrationOutcome) -> None:
        """A successful outcome's points: its wiring's latest sweep."""
        assert self.run is not None and outcome.success  # only a running goal's successful end
        self._sweeps[self.run.plan.wiring] = (outcome.points, outcome.failed)

    def calibrate(self, wirings: dict, homogeneous: str, nominal: Probe) -> ProbeCalibration:
        """The constants from every wiring's latest sweep (``wirings``: :class:`Wiring` by name,
        ``homogeneous`` the one that gives β0). ValueError or CalibrationError, with the reason,
        when the sweeps cannot determine them."""
        if homogeneous not in self._sweeps:
            raise ValueError("no sweep of the homogeneous wiring yet: β0 needs one")
        points, failed = [], {}
        for wiring_points, wiring_failed in self._sweeps.values():
            points += wiring_points
            failed.update(wiring_failed)
        return calibrate_probe(points, wirings, KnownConstants.of(nominal), homogeneous, failed, nominal.lever_m)

    def write_probe(self, bench: Bench, path: str, date: str | None = None) -> tuple[ProbeCalibration, str]:
        """The constants from every wiring's latest sweep (:meth:`calibrate`) written to the
        probe file at ``path`` with their record, dated ``date`` (None: now, UTC), and counted
        (:meth:`calibrated`); the calibration and the writer's report. A goal replaces the probe
        file of an earlier one, never a device, a FIFO or the bench's nominal probe file the
        calibration reads. CalibrationError, ValueError or OSError with the reason; nothing
        counted then."""
        calibration = self.calibrate(bench.wirings, bench.homogeneous, bench.nominal)
        date = date or datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
        record = calibration.record(date, bench.hardware_id)
        inputs = [bench.nominal_file] if bench.nominal_file else []
        written = calibration.probe().to_yaml(path, record, inputs=inputs, force=True)
        self.calibrated(calibration, path)
        return calibration, written

    def calibrated(self, calibration: ProbeCalibration, path: str) -> str:
        """Counts a calibration written to ``path``; the line that reports it."""
        self.calibrations += 1
        self.last = f"calibration {self.calibrations}: {calibration.report().splitlines()[0]} → {path}"
        return self.last


def _by_hand(action):
    """A cycle of the step said to be at the operator's turn; any other action as it is."""
    return dataclasses.replace(action, turned_by_hand=True) if isinstance(action, CycleRequest) else action
