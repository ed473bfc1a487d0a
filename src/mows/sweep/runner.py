"""A rotation sweep as an I/O-free state machine, in the manner of
:class:`mows.device.cycle.sequencer.CycleSequencer`: fed the goal, the driver's answers to cycle
requests, the ring-down fits and a cancel (:mod:`mows.sweep.events`, what it is fed and
returns), it returns steps (run a cycle at θ0, report feedback, decompose, publish the map, the
finished result). Who runs the cycles, delivers the fits and keeps the time is the caller's
business (the mapper node does it over ROS).

One sweep: for each orientation one driver cycle of ``repeats`` ring-downs; once the driver says
how many it recorded, their fits are collected (or the caller says their time is up); after the
last orientation every OK ring-down is decomposed (:func:`mows.sweep.probes.decompose_probes`)
with f00 taken as the mean of the estimator's own (frequency − shift).

An adaptive sweep (a goal with a ``target``) lets :class:`mows.sweep.planner.AdaptivePlanner`
choose each next orientation and its repeats from the ring-downs so far; the sweep is decomposed
whenever the planner's linearised prediction comes within ``DECOMPOSE_NEAR`` of the target, and
ends when a decomposition reaches it or the time budget holds no further cycle. Its device time
is read from the ring-downs' stamps (first to last, plus a turn and a ring-down).

The sweep's probes are those ``SweepSettings.probes`` lists (the estimator's list; one probe is
a set of one). It collects one fit per probe and ring-down, keeps
each probe's fits in a record of its own, with the step (the orientation's index) each was taken
at, and decomposes the probes' shares together (:mod:`mows.sweep.probes`). Several probes ring
together under the multi-tone drive, each fit measuring its swing, and the 3θ0 curvature is
fitted; a probe that has the coils to itself, listed or not, rings from the housing stop
(:mod:`mows.device.cycle.sequencer`). The angles it commands are the stage's; each
fit comes back at its probe's own θ0 (the stage's angle plus the probe's home orientation),
which the decomposition takes. Its feedback's shift is the first probe's at its own θ0 of this
orientation, its fits are all. Adaptive sweeps are of one probe.
"""

import dataclasses
import enum
import functools
import math

import numpy as np

from mows.device.cycle.phases import CycleRequest
from mows.estimate.probe_set import ProbeEntry
from mows.sweep.decompose import orientations_problem
from mows.sweep.decomposition import Decomposition
from mows.sweep.events import (
    REPEATS_PER_ANGLE_RANGE,
    CycleAnswer,
    SweepFeedback,
    SweepFit,
    SweepGoal,
    SweepMap,
    SweepOutcome,
    SweepSettings,
    SweepStep,
)
from mows.sweep.planner import AdaptivePlanner, PlanEnd
from mows.sweep.probes import (
    DecomposeOptions,
    ProbeSweep,
    decompose_probes,
    f00_of,
    problems,
    report,
    step_orientations_rad,
)
from mows.sweep.record import SweepRecord
from mows.sweep.shift_model import MODELS

DECOMPOSE_NEAR = 1.25  # decompose an adaptive sweep once the prediction is this close to the target


class SweepState(enum.StrEnum):
    """What :class:`SweepRunner` is doing; the values are what /diagnostics and the logs show."""

    IDLE = "idle"
    SWEEPING = "sweeping"
    DECOMPOSING = "decomposing"


class SweepRunner:
    """Runs one sweep at a time; ``state`` is a :class:`SweepState`."""

    def __init__(self) -> None:
        self.state = SweepState.IDLE
        self.sweeps = 0  # sweeps that came as far as the decomposition
        self.last = "no sweep yet"  # the last decomposition's report
        self.last_failure = ""  # why the last sweep failed ('' once one succeeds; a cancel leaves it)
        self.cancels = 0  # sweeps cancelled (by their client, or because it left)
        self.last_cancel = ""  # how the last sweep ended when it was cancelled, and why ('' once one ends otherwise)
        self._cancel_reason = ""
        self._angles: list[float] = []
        self._repeats = 0
        self._index = 0
        self._model = ""
        self._settings: SweepSettings | None = None
        self._probes: tuple[ProbeEntry, ...] = ()  # the running sweep's
        self._cancelled = False
        self._fits: dict[int, list[SweepFit]] = {}
        self._awaited: CycleAnswer | None = None  # the cycle whose fits are being collected
        self._records: dict[int, SweepRecord] = {}  # each probe's, by id
        self._record = SweepRecord()  # the first probe's
        self._steps: dict[int, list[int]] = {}  # the step of each point of each record
        self._shares: list[ProbeSweep] = []  # the probes' shares being decomposed
        self._planner: AdaptivePlanner | None = None  # an adaptive sweep's
        self._decomposition: Decomposition | None = None
        self._decomposed_points = 0
        self._turning: CycleRequest | None = None  # the cycle that waits for the operator's turn
        self._cycle_ids: list[int] = []  # the cycles of the sweep so far

    # --- inputs ----------------------------------------------------------------------------
    def start(self, goal: SweepGoal, settings: SweepSettings) -> None:
        """Accept ``goal`` (the sweep begins at :meth:`begin`). ValueError, with the reason, when
        it is refused: a non-finite angle, too few distinct orientations to decompose, repeats
        outside :data:`REPEATS_PER_ANGLE_RANGE`, an unknown model, or a sweep still running."""
        given = [float(a) for a in goal.theta0_rad]
        angles = given or list(np.radians(np.arange(0.0, 360.0, settings.angle_step_deg)))
        problems = []
        low, high = REPEATS_PER_ANGLE_RANGE
        if goal.repeats_per_angle and not low <= goal.repeats_per_angle <= high:
            problems.append(f"repeats_per_angle={goal.repeats_per_angle!r} is outside [{low}, {high}]")
        if not all(math.isfinite(a) for a in angles):
            problems.append(f"angles {angles} are not all finite")
        elif problem := orientations_problem(angles, settings.f00_free):
            problems.append(problem)
        if goal.model and goal.model not in MODELS:
            problems.append(f"model {goal.model!r} is not one of {', '.join(MODELS)}")
        if self.state != SweepState.IDLE:
            problems.append(f"another sweep is still running ({self.state})")
        if goal.target is not None and len(settings.probes) > 1:
            problems.append(f"an adaptive sweep is of one probe; {len(settings.probes)} are listed")
        planner = None
        if goal.target is not None and not problems:
            try:
                planner = AdaptivePlanner(
                    settings.probes[0].probe,
                    settings.probes[0].f00_hz,
                    goal.target,
                    settings.repeat_s,
                    settings.turn_s,
                    candidates_rad=given or None,
                    f00_free=settings.f00_free,
                )
            except ValueError as refused:
                problems.append(str(refused))
        if problems:
            raise ValueError("; ".join(problems))
        self.state, self._settings = SweepState.SWEEPING, settings
        self._probes = settings.probes
        self._planner, self._decomposition, self._decomposed_points = planner, None, 0
        self._angles = [] if planner else angles
        self._repeats = goal.repeats_per_angle or settings.repeats_per_angle
        self._model = goal.model or settings.model
        self._index, self._cancelled, self._awaited, self._turning = 0, False, None, None
        self._fits.clear()
        self._cycle_ids = []
        self._records = {entry.probe_id: SweepRecord() for entry in self._probes}
        self._steps = {entry.probe_id: [] for entry in self._probes}
        self._record = self._records[self._probes[0].probe_id]

    @property
    def settings(self) -> SweepSettings:
        """The settings of the sweep accepted last; RuntimeError before the first."""
        if self._settings is None:
            raise RuntimeError("no sweep has been started")
        return self._settings

    def begin(self) -> SweepStep:
        """The accepted sweep's first step."""
        return self._next_orientation(SweepStep())

    def cancel(self, reason: str = "") -> None:
        """End the sweep before its next orientation, or with no map once a decomposition
        under way returns; ``reason`` ('' for its client's own cancel) goes into ``last_cancel``."""
        if self.state != SweepState.IDLE and not self._cancelled:
            self._cancelled, self._cancel_reason = True, reason

    def cancelled(self) -> bool:
        """Whether a cancel came for the running sweep."""
        return self._cancelled

    @property
    def turn_awaited(self) -> float | None:
        """The orientation (rad) the operator has been asked to turn the stage to, if any."""
        return None if self._turning is None else self._turning.theta0_rad

    def turn_timed_out(self, timeout_s: float) -> SweepStep:
        """No confirmation of the awaited turn came within ``timeout_s``: the sweep ends, failed."""
        if self._turning is None:
            return SweepStep()
        theta0_deg = math.degrees(self._turning.theta0_rad)
        return self.abandon(f"no confirmation of θ0 = {theta0_deg:g}° within {timeout_s:g} s")

    def on_turned(self) -> SweepStep:
        """The operator confirmed the turn the last step asked for: its cycle (or the end, if
        the sweep was cancelled meanwhile)."""
        call, self._turning = self._turning, None
        if self.state != SweepState.SWEEPING or call is None:
            return SweepStep()
        if self._cancelled:
            return self._end(
                SweepStep(), SweepOutcome(False, f"cancelled before orientation {self._index}", cancelled=True)
            )
        return SweepStep(run_cycle=call)

    def _cycle(self, step: SweepStep, call: CycleRequest) -> SweepStep:
        """Run ``call`` next, after the operator's turn when the stage has no motor (the cycle
        then says the stage was turned by hand)."""
        if self.settings.manual_orientation:
            self._turning, step.turn = dataclasses.replace(call, turned_by_hand=True), call.theta0_rad
        else:
            step.run_cycle = call
        return step

    def on_cycle(self, answer: CycleAnswer) -> SweepStep:
        if self.state != SweepState.SWEEPING:
            return SweepStep()
        if answer.problem:
            where = f"orientation {self._index} ({math.degrees(self._angles[self._index]):.1f}°)"
            if self._cancelled:  # the cycle stopped because the sweep was cancelled: no failure
                return self._end(SweepStep(), SweepOutcome(False, f"cancelled during {where}", cancelled=True))
            return self.abandon(f"{where}: {answer.problem}")
        self._awaited = answer
        return self._collected() or SweepStep()

    def on_fit(self, fit: SweepFit) -> SweepStep | None:
        """A fit from the stream; a step once the awaited cycle's fits are all in."""
        # Fits of cycles run by others between sweeps, tuning ring-downs, and fits of probes not
        # the sweep's (the estimator reports an id it does not know) are not ours.
        if self.state != SweepState.SWEEPING or fit.tuning or fit.probe_id not in self._records:
            return None
        self._fits.setdefault(fit.cycle_id, []).append(fit)
        return self._collected()

    def fits_time_up(self) -> SweepStep | None:
        """The awaited cycle's fits are late: go on with those that came."""
        if self.state != SweepState.SWEEPING or self._awaited is None:
            return None
        return self._orientation_done()

    def abandon(self, reason: str) -> SweepStep:
        """End the sweep as failed, with ``reason`` (the caller cannot go on)."""
        if self.state == SweepState.IDLE:
            return SweepStep()
        return self._end(SweepStep(), SweepOutcome(False, reason))

    def on_decomposed(self, decompositions: list[Decomposition]) -> SweepStep:
        """The result of the step's ``decompose``, each probe's decomposition: the maps to publish,
        when one succeeded (a failed one has no numbers to show, but beside others it shows its
        probe's status), and the sweep's end (an adaptive sweep goes on unless the planner ends it).
        A sweep cancelled meanwhile publishes nothing: nobody waits for its map."""
        if self._cancelled:
            where = f"while decomposing {len(self._cycle_ids)} orientations"
            return self._end(SweepStep(), SweepOutcome(False, f"cancelled {where}", cancelled=True))
        if self._planner is not None:
            self._decomposition, self._decomposed_points = decompositions[0], len(self._record.points)
            self.state = SweepState.SWEEPING
            return self._next_planned(SweepStep())
        self.last = report(self._shares, decompositions)
        cycles = tuple(self._cycle_ids)
        maps = tuple(
            SweepMap(self.sweeps, d, s.record, s.f00_hz, s.probe_id, cycles)
            for s, d in zip(self._shares, decompositions)
        )
        ok = all(d.ok for d in decompositions)
        outcome = SweepOutcome(ok, problems(self._shares, decompositions) or self.last, maps=maps)
        published = maps if any(d.ok for d in decompositions) else ()
        return self._end(SweepStep(publish=published), outcome)

    # --- the sweep -------------------------------------------------------------------------
    def _collected(self) -> SweepStep | None:
        answer = self._awaited
        expected = answer.ringdowns_recorded * len(self._probes) if answer else 0
        if answer is None or len(self._fits.get(answer.cycle_id, ())) < expected:
            return None
        return self._orientation_done()

    def _orientation_done(self) -> SweepStep:
        answer, self._awaited = self._awaited, None
        assert answer is not None  # only called once the awaited cycle has answered
        fits = self._fits.pop(answer.cycle_id, [])
        self._cycle_ids.append(answer.cycle_id)
        theta0 = self._angles[self._index]
        before = len(self._record.points)
        for fit in fits:
            record = self._records[fit.probe_id]
            if fit.point is None:
                record.failed += 1
            else:
                record.add(fit.point)
                self._steps[fit.probe_id].append(self._index)
        # A probe's fits are at its own θ0, not the stage's: that of its new points, if any.
        new = self._record.points[before:]
        shift, std, n_ok = self._record.at_angle(new[0].theta0_rad if new else theta0)
        step = SweepStep(
            feedback=SweepFeedback(
                self._index, len(self._angles), theta0, shift, std, n_ok, tuple(f.source for f in fits)
            )
        )
        self._index += 1
        return self._next_orientation(step)

    def _next_orientation(self, step: SweepStep) -> SweepStep:
        if self._planner is not None:
            return self._next_planned(step)
        if self._cancelled:  # the last orientation's too: nobody waits for the map
            outcome = SweepOutcome(
                False, f"cancelled after {self._index} of {len(self._angles)} orientations", cancelled=True
            )
            return self._end(step, outcome)
        if self._index == len(self._angles):
            return self._measured(step)
        return self._cycle(step, CycleRequest(self._angles[self._index], self._repeats))

    def _measured(self, step: SweepStep) -> SweepStep:
        self.sweeps += 1
        records = self._records.values()
        if not any(r.points for r in records):
            failed = sum(r.failed for r in records)
            return self._end(step, SweepOutcome(False, f"no successful ring-down in the sweep ({failed} failed)"))
        return self._decomposing(step)

    def _decomposing(self, step: SweepStep) -> SweepStep:
        """``step`` with the decomposition of every probe's share of the sweep so far."""
        self.state = SweepState.DECOMPOSING
        self._shares = [
            ProbeSweep.of_entry(e, self._records[e.probe_id], self._steps[e.probe_id]) for e in self._probes
        ]
        # Several probes share the coils' multi-tone drive; one alone rings from the stop (module docstring).
        shared = len(self._probes) > 1
        options = DecomposeOptions(self._model, self.settings.f00_free, curvature=shared, measured_swings=shared)
        orientations = step_orientations_rad(self._shares, self._angles)
        step.decompose = functools.partial(decompose_probes, self._shares, options, orientations_rad=orientations)
        return step

    # --- an adaptive sweep -------------------------------------------------------------------
    def _next_planned(self, step: SweepStep) -> SweepStep:
        planner = self._planner
        assert planner is not None  # an adaptive sweep, set by start()
        if self._cancelled:
            return self._end(step, SweepOutcome(False, f"cancelled after {self._index} cycles", cancelled=True))
        if self._decomposition_due(planner):
            return self._decomposing(step)
        choice = planner.next(self._record, self._decomposition, self._elapsed_s())
        if isinstance(choice, PlanEnd):
            return self._planned_end(step, choice)
        self._angles.append(choice.theta0_rad)
        self._repeats = choice.repeats
        return self._cycle(step, CycleRequest(choice.theta0_rad, choice.repeats))

    def _decomposition_due(self, planner: AdaptivePlanner) -> bool:
        """New ring-downs at enough orientations, and a prediction near the target."""
        points = self._record.points
        if len(points) == self._decomposed_points or orientations_problem(
            [p.theta0_rad for p in points], self.settings.f00_free
        ):
            return False
        targets = planner.goal.targets()
        asked = np.isfinite(targets)
        predicted = planner.predicted_std(self._record, self._decomposition)
        return self._decomposition is None or bool(np.all(predicted[asked] <= DECOMPOSE_NEAR * targets[asked]))

    def _elapsed_s(self) -> float:
        """Device time of the sweep so far, from its ring-downs' stamps: first to last, plus the
        first turn and the last ring-down's whole cost (its kick came before its stamp)."""
        points = self._record.points
        if not points:
            return 0.0
        stamps = [p.t_s for p in points]
        return max(stamps) - min(stamps) + self.settings.turn_s + self.settings.repeat_s

    def _planned_end(self, step: SweepStep, end: PlanEnd) -> SweepStep:
        self.sweeps += 1
        decomposition = self._decomposition
        if decomposition is None or not decomposition.ok:
            return self._end(step, SweepOutcome(False, end.message))
        self.last = decomposition.report()
        step.publish = (
            SweepMap(self.sweeps, decomposition, self._record, f00_of(self._record), cycle_ids=tuple(self._cycle_ids)),
        )
        return self._end(step, SweepOutcome(end.reached, end.message, maps=step.publish))

    def _end(self, step: SweepStep, outcome: SweepOutcome) -> SweepStep:
        self.state, self._awaited, self._turning = SweepState.IDLE, None, None
        if outcome.cancelled:
            reason = f" ({self._cancel_reason})" if self._cancel_reason else ""
            self.cancels, self.last_cancel = self.cancels + 1, outcome.message + reason
        else:
            self.last_failure, self.last_cancel = ("" if outcome.ok else outcome.message), ""
        self._fits.clear()
        step.finished = outcome
        return step
