"""The measurement cycle as a state machine over device sample indices, for the probes of one
shared stage (``probes``, at their home orientations; probe id = index), one probe a stage of one.

One cycle at one orientation θ0 (the stage angle; each probe at its home orientation plus it):
turn the stage and let it settle; then ``tuning_steps + repeats`` rounds, each exciting the
round's groups of tones in turn under the duty-cycle limit and recording each group's free
ring-down, with a pause of ``gap_s`` between a ring-down and the next excitation.

Each round is planned at the stage angle (:func:`mows.device.cycle.excitation.plan_at`), every
probe's tone at its own resonance estimate: a tone that rings no other probe driven alone to
the housing stop at ``excitation_current_a``, cut at its drive's turning point; tones that ring
each other sized for a swing and grouped under the driver's cap, overlapping ones refused with
the reason (:mod:`mows.device.cycle.excitation`). The groups are excited in turn
(:class:`mows.device.cycle.tone_groups.GroupSequence`). The first ``tuning_steps`` rounds'
ring-downs are fitted by the fit function the sequencer is handed (the estimator's joint fit of
the probes ringing in one window, in the driver), each probe's good fit retuning its estimate
where its line lies nearer that estimate than any other probe's (else it is a neighbour's line,
and retunes none); the next ``repeats`` rounds are the measurements. Probes the plan refuses are named with the
reason in the outcome while the others are measured; a cycle whose probes are all refused is
refused before it starts. The EXCITING and RINGDOWN of a group list its probes, each one's tone
and its own θ0.

Each probe's estimate starts at its f00 and carries from cycle to cycle. A single frequency (the
sequencer's ``frequency_hz``, a request's ``frequency_hz``) is a resonance estimate of one probe:
the probe whose estimate is nearest it takes it (the stage's probe, when it carries one).

Time is the device's sample index. Every command is scheduled at a sample, and every phase
is stamped with the sample at which the device *answered* that its command took effect, so
that the stamp of a ring-down is the sample the coils went off, exact to one sample. A phase
is announced once the samples have reached it.

The sequencer does no I/O: it is fed samples, command results and link changes, and returns
a :class:`~mows.device.cycle.phases.CycleStep` of commands to send, phase events to publish,
the outcome of a finished cycle, and whether the coils must go off at once. The coils are on
only in EXCITING: every other phase is coils off, and a fault (emergency stop, a refused or
unanswered command, a lost link) switches them off at once, every tone together; the groups
not yet excited are dropped, and the time the coils were on counts towards the duty limit. The
emergency stop latches until released.

Why this module is over 450 lines: it is one state machine. Its inputs, the cycle it runs as a
generator and the waits that resume that generator share the machine's state (the commands in
flight, the samples' anchor, the duty limit, the phase announced); split, each part would reach
into the others'. What an excitation drives (``excitation``), what a cycle waits for and records
(``waits``) and the groups in turn (``tone_groups``) are apart.
"""

from __future__ import annotations

from collections.abc import Generator, Sequence

from mows.device.cycle.duty import DutyCycleLimit
from mows.device.cycle.excitation import Excitation, StagePlan, group_excitation, plan_at, refusals
from mows.device.cycle.phases import (
    CycleOutcome,
    CyclePlan,
    CycleRequest,
    CycleSettings,
    CycleStep,
    LostTuning,
    NeighbourLine,
    Phase,
    PhaseEvent,
    TuningFit,
    TuningResult,
    check_setting,
)
from mows.device.cycle.tone_groups import GroupSequence, with_cap
from mows.device.cycle.waits import Answer, CycleAborted, Reach, Recording, Run
from mows.device.interface import (
    CoilCommand,
    Command,
    CommandResult,
    LinkEvent,
    OrientationCommand,
)
from mows.physics.coils import CoilSetup, CurrentCap
from mows.physics.coupling import PlacedProbe
from mows.physics.multitone import ExcitationPlan, Tone
from mows.records.samples import SampleBlock


class CycleSequencer:
    """Runs one cycle at a time on a device of ``sample_rate_hz`` with the coils of ``setup``
    (module docstring).

    ``probes`` are the probes of one shared stage at their home orientations; ``frequency_hz``
    a first resonance estimate, of the probe whose f00 is nearest it (module docstring);
    ``lead_samples`` how far ahead of the newest sample commands are scheduled; ``cap`` the
    driver's coil current cap (no command above it is ever issued, a multi-tone drive's summed
    peak included); ``fit`` fits a tuning ring-down (:data:`mows.device.cycle.phases.TuningFit`).
    """

    def __init__(
        self,
        settings: CycleSettings,
        setup: CoilSetup,
        cap: CurrentCap,
        sample_rate_hz: float,
        frequency_hz: float,
        lead_samples: int = 0,
        *,
        fit: TuningFit,
        probes: Sequence[PlacedProbe],
        last_cycle_id: int = 0,
    ):
        if not probes:
            raise ValueError("a cycle needs the probes it rings")
        self.settings = settings
        self.setup = setup
        self.cap = cap
        self.sample_rate_hz = float(sample_rate_hz)
        self.lead_samples = int(lead_samples)
        self.probes = tuple(probes)
        # Each probe's resonance estimate, retuned by its tuning fits (module docstring).
        self.frequencies_hz, self._named = _named(tuple(p.probe.f00_hz for p in self.probes), frequency_hz)
        self.latched: str | None = None  # the reason of a latched emergency stop
        self.phase = Phase.IDLE
        self.fault = ""  # why the last cycle failed, until the next one starts or a stop is released
        self._fit = fit
        self._duty = DutyCycleLimit(settings.max_duty_cycle, self._samples(settings.duty_window_s))
        self._anchor: tuple[int, int] | None = None  # (sample index, stamp ns) of a received sample
        self._next_index = 0
        self._cycle: CyclePlan | None = None
        self._runner: Run | None = None
        self._wait: Reach | Answer | None = None
        self._results: dict[int, CommandResult] = {}
        self._recordings: list[Recording] = []
        self._groups: GroupSequence | None = None  # the running round's groups
        self._unstamped: list[tuple[Phase, str]] = []  # events raised before the first sample
        self._last_cycle_id = last_cycle_id  # ids go on from another sequencer's (the driver reconfigured)
        self._last_command_id = 0
        self._recorded = 0  # the running cycle's measurement ring-downs recorded whole so far
        self._coils_stopped_at: int | None = None  # our next sample when coils were last switched off now
        self._step = CycleStep()
        self._announce(Phase.IDLE, "driver started")

    # --- inputs ----------------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        return self._runner is not None

    @property
    def next_index(self) -> int:
        return self._next_index

    @property
    def last_cycle_id(self) -> int:
        """The id of the cycle started last (0 before the first)."""
        return self._last_cycle_id

    def duty_fraction(self) -> float:
        """Share of the last duty window with the coils on."""
        return self._duty.fraction(self._next_index)

    def start(self, request: CycleRequest) -> CycleStep:
        """Begin a cycle. ValueError, with the reason, if it cannot run."""
        cycle = self._plan(request)
        self._step = CycleStep()
        self.fault = ""
        self._cycle = cycle
        self._runner = self._run(cycle)
        self._advance(None)
        return self._take_step()

    def on_samples(self, chunk: SampleBlock) -> CycleStep:
        self._anchor = (chunk.first_sample_index, chunk.stamp_ns)
        self._next_index = chunk.end_index
        for recording in self._recordings:
            recording.add(chunk)
        for phase, reason in self._unstamped:  # they hold from the first sample on
            self._emit(phase, chunk.first_sample_index, reason=reason)
        self._unstamped.clear()
        self._resume()
        return self._take_step()

    def on_result(self, result: CommandResult) -> CycleStep:
        if self.busy:  # an answer that comes after its cycle failed has nobody waiting
            self._results[result.command_id] = result
            self._resume()
        return self._take_step()

    def on_link(self, event: LinkEvent) -> CycleStep:
        if not event.up and self.busy:
            self._fault(f"link to the device lost: {event.reason}")
        return self._take_step()

    def abort(self, reason: str) -> CycleStep:
        """End the running cycle (coils off at once): the samples stopped, the driver stops."""
        if self.busy:
            self._fault(reason)
        return self._take_step()

    def cancel(self, reason: str) -> CycleStep:
        """End the running cycle because nobody wants it any more (coils off at once): it
        fails with ``reason``, and the sequencer is IDLE, not in FAULT."""
        if self.busy:
            self._stop(f"cancelled: {reason}", cancelled=True)
            self._announce(Phase.IDLE, f"cancelled: {reason}")
        return self._take_step()

    def emergency_stop(self, reason: str) -> CycleStep:
        """Coils off at once, the running cycle failed, and no cycle until :meth:`release`."""
        self.latched = reason or "no reason given"
        self._fault(f"emergency stop: {self.latched}")
        return self._take_step()

    def release(self) -> CycleStep:
        if self.latched is not None:
            self.latched, self.fault = None, ""
            self._announce(Phase.IDLE, "emergency stop released")
        return self._take_step()

    # --- the cycle -------------------------------------------------------------------------
    def _plan(self, request: CycleRequest) -> CyclePlan:
        if self.latched is not None:
            raise ValueError(f"emergency stop latched ({self.latched}); release it before a cycle")
        if self.busy:
            assert self._cycle is not None  # set and cleared together with _runner (start, _end)
            raise ValueError(f"cycle {self._cycle.cycle_id} is still running")
        if self._anchor is None:
            raise ValueError("no samples from the device yet")
        s = self.settings if request.settings is None else request.settings
        cycle = CyclePlan.resolve(self._last_cycle_id + 1, request, s)  # ValueError for a request out of range
        frequencies_hz, named = self.frequencies_hz, self._named
        if request.frequency_hz is not None:
            nyquist_hz = self.sample_rate_hz / 2.0
            check_setting(
                "frequency_hz",
                request.frequency_hz,
                0.0 < request.frequency_hz < nyquist_hz,
                f"in (0, {nyquist_hz:g}) Hz",
            )
            frequencies_hz, named = _named(frequencies_hz, request.frequency_hz)
        self._duty.configure(s.max_duty_cycle, self._samples(s.duty_window_s))
        # ValueError above the cap, when it excites no probe or never fits the duty limit.
        self._groups_of(self._plan_at(cycle, frequencies_hz))
        self.frequencies_hz, self._named = frequencies_hz, named
        self._last_cycle_id = cycle.cycle_id
        return cycle

    def _run(self, c: CyclePlan) -> Run:
        coils_free = yield from self._turn_and_settle(c)
        fits: list[TuningResult] = []
        rung = self._recorded = 0
        for k in range(c.tuning_steps + c.repeats):
            tuning = k < c.tuning_steps
            index = k if tuning else k - c.tuning_steps
            try:  # each round at the estimates the last one's tuning left
                stage = self._plan_at(c, self.frequencies_hz)
                self._groups = self._groups_of(stage)
            except ValueError as refused:
                raise CycleAborted(f"round {k + 1} cannot be excited: {refused}") from refused
            for _ in stage.plan.groups:
                gap = self._samples(c.gap_s) if rung else 0
                group = self._groups.next(max(coils_free + gap, self._next_index + self.lead_samples))
                assert group is not None  # a group is asked for only while some remain
                to_stop = group.probe_ids[0] in stage.to_stop
                excitation = group_excitation(self.setup, group, self.sample_rate_hz, to_stop)
                recording = yield from self._excite(c, excitation, coils_free, index, tuning)
                rung += 1
                if tuning:
                    fits += self._tune(recording, group.tones)
                else:
                    self._recorded += 1
                coils_free = recording.end
        self._groups = None
        yield from self._enter(c, Phase.IDLE, coils_free, 0)
        return self._outcome(c, stage.plan, self._recorded, fits)

    def _plan_at(self, c: CyclePlan, frequencies_hz: tuple[float, ...]) -> StagePlan:
        return plan_at(self.probes, c.theta0_rad, self.setup, self.cap, c.settings, frequencies_hz)

    def _groups_of(self, stage: StagePlan) -> GroupSequence:
        """The groups of ``stage`` under the driver's cap and the duty limit (ValueError if a group
        is above the cap or never fits the limit)."""
        return GroupSequence(stage.plan, self._capped_setup(), self._duty, self.sample_rate_hz, stage.to_stop)

    def _excite(
        self, c: CyclePlan, e: Excitation, coils_free: int, index: int, tuning: bool
    ) -> Generator[Answer | Reach, CommandResult | None, Recording]:
        """Excite ``e`` and record its ring-down, announcing GAP (if it waits), EXCITING and
        RINGDOWN; returns the ring-down's recording, complete if a tuning fit needs its samples.
        The duty limit counts the interval the device applied."""
        on = self._issue(CoilCommand, e.on_index, tones=e.tones, samples=e.off_index - e.on_index)
        off = self._issue(CoilCommand, e.off_index)
        if e.on_index > coils_free:
            yield from self._enter(c, Phase.GAP, coils_free, e.on_index - coils_free, index, tuning)
        switched_on = yield from self._answer(on)
        switched_off = yield from self._answer(off)
        assert self._groups is not None  # the round's groups, until the cycle ends
        self._groups.switched(switched_on, switched_off)  # the duty limit counts what the device applied
        recording = Recording(switched_off, switched_off + self._samples(c.settings.ringdown_s))
        if tuning:
            self._recordings.append(recording)
        yield from self._enter(c, Phase.EXCITING, switched_on, switched_off - switched_on, index, tuning, e)
        yield from self._enter(c, Phase.RINGDOWN, switched_off, recording.end - switched_off, index, tuning, e)
        yield Reach(recording.end)
        if tuning:
            self._recordings.remove(recording)
        return recording

    def _outcome(self, c: CyclePlan, plan: ExcitationPlan, recorded: int, fits: list) -> CycleOutcome:
        groups = (plan.group_tones(g) for g in range(len(plan.groups)))
        in_turn = " then ".join(str([f"{t.probe_id}: {t.frequency_hz:.4f} Hz" for t in tones]) for tones in groups)
        message = f"{recorded} ring-downs recorded of the probes {in_turn}"
        failed = [f for f in fits if not f.ok]
        if failed:
            message += f"; {len(failed)} of {len(fits)} tuning fits failed ({failed[-1].report()})"
        if plan.refused:
            message += f"; refused: {refusals(plan)}"
        frequency_hz = plan.group_tones(0)[0].frequency_hz
        return CycleOutcome(True, message, c.cycle_id, frequency_hz, recorded, tuple(fits), plan.refused)

    def _turn_and_settle(self, c: CyclePlan) -> Generator[Answer | Reach, CommandResult | None, int]:
        """Turn to the cycle's θ0 and let it settle (SETTLING); returns the sample from which the
        coils are off and nothing is scheduled. After coils were switched off now (a cancelled or
        failed cycle), the switch-off applies at the device's next sample, which runs up to a
        command lead ahead of the samples received: the turn waits until they have passed it, as
        a device refuses to turn the probe while its coils are on."""
        switched_off = None if self._coils_stopped_at is None else self._coils_stopped_at + self.lead_samples + 1
        if switched_off is not None and self._next_index < switched_off:
            yield Reach(switched_off)  # the samples up to the switch-off's received
        turned = yield from self._answer(
            self._issue(
                OrientationCommand,
                self._next_index + self.lead_samples,
                theta0_rad=c.theta0_rad,
                by_hand=c.turned_by_hand,
            )
        )
        settle = self._samples(c.settings.turn_settle_s)
        yield from self._enter(c, Phase.SETTLING, turned, settle)
        return turned + settle

    def _tune(self, recording: Recording, tones: Sequence[Tone]) -> list[TuningResult]:
        """Fit a tuning ring-down of ``tones``' probes; each good fit becomes its probe's
        estimate, unless its line lies nearer another probe's estimate than its own (any probe
        of the stage, rung in this window or not: a neighbour driven off its resonance, or
        refused beside this tone, rings too): then it is that probe's line, and retunes none."""
        if not recording.complete:
            return [LostTuning() for _ in tones]
        samples, saturated = recording.arrays()
        theta0_rad = tuple(t.theta0_rad for t in tones)
        expected_hz = tuple(t.frequency_hz for t in tones)
        fits: list[TuningResult] = list(
            self._fit(samples, self.sample_rate_hz, theta0_rad, expected_hz, saturated=saturated)
        )
        before, estimates = self.frequencies_hz, list(self.frequencies_hz)
        for k, (tone, fit) in enumerate(zip(tones, fits, strict=True)):
            if not fit.ok:
                continue
            owner = _nearest(before, fit.frequency_hz)
            if owner == tone.probe_id:
                estimates[owner] = float(fit.frequency_hz)
            else:
                own = before[tone.probe_id]
                fits[k] = NeighbourLine(tone.probe_id, float(fit.frequency_hz), own, owner, before[owner])
        self.frequencies_hz = tuple(estimates)
        return fits

    def _capped_setup(self) -> CoilSetup:
        """The setup under the driver's cap, which a multi-tone plan holds on the summed peak."""
        return with_cap(self.setup, self.cap.limit_a)

    @property
    def frequency_hz(self) -> float:
        """The estimate of the probe the last single frequency named (reported outside an excitation)."""
        return self.frequencies_hz[self._named]

    # --- waiting ---------------------------------------------------------------------------
    def _issue(self, kind, at_index: int, **fields) -> Command:
        self._last_command_id += 1
        command = kind(self._last_command_id, int(at_index), **fields)
        self._step.commands.append(command)
        return command

    def _answer(self, command: Command) -> Generator[Answer, CommandResult | None, int]:
        deadline = max(command.at_sample_index, self._next_index) + self._samples(self.settings.confirm_timeout_s)
        result = yield Answer(command, deadline)
        assert result is not None  # _resume resumes an Answer only with its command's result
        if not result.accepted:
            raise CycleAborted(f"the device refused {type(command).__name__} {command.command_id}: {result.reason}")
        return result.applied_sample_index

    def _enter(
        self,
        c: CyclePlan,
        phase: Phase,
        index: int,
        duration_samples: int,
        repeat_index: int = 0,
        tuning: bool = False,
        excitation: Excitation | None = None,
    ) -> Generator[Reach, CommandResult | None, None]:
        yield Reach(index + 1)
        self._emit(
            phase,
            index,
            cycle=c,
            duration_samples=duration_samples,
            repeat_index=repeat_index,
            tuning=tuning,
            excitation=excitation,
        )

    def _resume(self) -> None:
        while self._runner is not None:
            wait = self._wait
            assert wait is not None  # a running cycle always waits: _advance keeps what it yields
            if isinstance(wait, Reach):
                if self._next_index < wait.index:
                    return
                value: CommandResult | None = None
            else:
                value = self._results.pop(wait.command.command_id, None)
                if value is None:
                    if self._next_index > wait.deadline_index:
                        self._fault(
                            f"the device did not answer {type(wait.command).__name__} "
                            f"{wait.command.command_id} in {self.settings.confirm_timeout_s:g} s"
                        )
                    return
            self._advance(value)

    def _advance(self, value: CommandResult | None) -> None:
        assert self._runner is not None  # called by start and _resume, with a cycle running
        try:
            self._wait = self._runner.send(value)
        except StopIteration as finished:
            self._end(finished.value)
        except CycleAborted as aborted:
            self._fault(str(aborted))

    def _end(self, outcome: CycleOutcome) -> None:
        self._step.outcome = outcome
        self._runner, self._wait, self._cycle = None, None, None
        self._recordings.clear()
        self._results.clear()

    def _fault(self, reason: str) -> None:
        """Coils off now; the running cycle (if any) fails with ``reason``, a fault. Its phases end
        with this FAULT (it carries the cycle's id: a record of the cycle ends with its fault)."""
        cycle = self._cycle
        self._stop(reason)
        self.fault = reason
        self._announce(Phase.FAULT, reason, cycle)

    def _stop(self, reason: str, cancelled: bool = False) -> None:
        """Coils off now, every tone together; the running cycle (if any) fails with ``reason``.
        The groups not yet excited are dropped, and the time the coils were on counts towards the
        duty limit."""
        self._step.coils_off_now = True
        self._coils_stopped_at = self._next_index
        if self._groups is not None:  # an excitation in flight counts up to now
            self._groups.emergency_stop(self._next_index, reason or "stopped")
        self._groups = None
        if self._runner is not None:
            cycle = self._cycle
            assert cycle is not None  # set and cleared together with _runner (start, _end)
            self._runner.close()
            self._end(
                CycleOutcome(False, reason, cycle.cycle_id, self.frequency_hz, self._recorded, cancelled=cancelled)
            )

    # --- events ----------------------------------------------------------------------------
    def _announce(self, phase: Phase, reason: str, cycle: CyclePlan | None = None) -> None:
        """A phase that begins at the device's next sample (known only once samples arrive;
        a cycle runs only once they have)."""
        if self._anchor is None:
            self._unstamped.append((phase, reason))
        else:
            self._emit(phase, self._next_index, cycle, reason=reason)

    def _emit(
        self,
        phase: Phase,
        index: int,
        cycle: CyclePlan | None = None,
        duration_samples: int = 0,
        repeat_index: int = 0,
        tuning: bool = False,
        reason: str = "",
        excitation: Excitation | None = None,
    ) -> None:
        """Announce ``phase``; an EXCITING and its RINGDOWN carry their ``excitation``: its
        currents (EXCITING only), its drive's frequency and the probes it rings, each with its
        tone and its θ0."""
        self.phase = phase
        # Events are stamped once samples have come (_announce holds them back until then);
        # a cycle's own events come later still, as _plan starts none before the first sample.
        assert self._anchor is not None
        anchor_index, anchor_ns = self._anchor
        currents = excitation.currents_a if excitation is not None and phase == Phase.EXCITING else ()
        tones = excitation.tones if excitation is not None else ()
        self._step.events.append(
            PhaseEvent(
                phase=phase,
                sample_index=index,
                stamp_ns=anchor_ns + round((index - anchor_index) * 1e9 / self.sample_rate_hz),
                cycle_id=cycle.cycle_id if cycle else 0,
                repeat_index=repeat_index,
                repeats=cycle.repeats if cycle else 0,
                tuning=tuning,
                currents_a=currents or (0.0,) * len(self.setup.phases_rad),
                frequency_hz=excitation.frequency_hz if excitation is not None else self.frequency_hz,
                theta0_rad=cycle.theta0_rad if cycle else 0.0,
                planned_duration_s=duration_samples / self.sample_rate_hz,
                setup=self.setup.name,
                reason=reason,
                probe_ids=tuple(t.probe_id for t in tones),
                probe_frequency_hz=tuple(t.frequency_hz for t in tones),
                probe_theta0_rad=excitation.theta0_rad if excitation is not None else (),
            )
        )

    def _take_step(self) -> CycleStep:
        step, self._step = self._step, CycleStep()
        return step

    def _samples(self, seconds: float) -> int:
        return int(round(seconds * self.sample_rate_hz))


def _named(estimates_hz: tuple[float, ...], frequency_hz: float) -> tuple[tuple[float, ...], int]:
    """``estimates_hz`` with the one nearest ``frequency_hz`` replaced by it, and its index
    (module docstring)."""
    k = _nearest(estimates_hz, frequency_hz)
    return tuple(float(frequency_hz) if j == k else f for j, f in enumerate(estimates_hz)), k


def _nearest(estimates_hz: tuple[float, ...], frequency_hz: float) -> int:
    """The probe whose estimate is nearest ``frequency_hz`` (the first of equals)."""
    return min(range(len(estimates_hz)), key=lambda j: abs(estimates_hz[j] - frequency_hz))
