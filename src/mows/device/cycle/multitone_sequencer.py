"""The measurement cycle of several probes on one shared stage: :class:`MultiToneSequencer`,
the sibling of :class:`mows.device.cycle.sequencer.CycleSequencer` (its inputs, waits, faults and events
are that sequencer's; only the cycle itself differs).

One cycle at stage angle θ turns the stage (every probe to its home orientation plus θ) and
lets the probes settle, then plans the excitation at that angle
(:func:`mows.device.cycle.tone_groups.plan_probes`: each probe's tone at its f00 for a swing, each at
most ``excitation_current_a``, groups whose summed peak stays within the driver's cap, the
overlapping tones refused with the reason). Each of ``repeats`` rounds excites the groups in
turn under the duty limit (:class:`mows.device.cycle.tone_groups.GroupSequence`), with ``gap_s``
between a ring-down and the next excitation, and records each group's ring-down. The
EXCITING and RINGDOWN of a group list its probes, each one's tone and its own θ0.

The probes are driven at the scene's f00: no tuning ring-downs are run (a tuning step would
retune one frequency, and a multi-tone cycle has one per probe). Probes the plan refuses are
named with the reason in the cycle's outcome while the others are measured; a cycle whose
probes are all refused is refused before it starts. An emergency stop switches every tone
off at once and drops the groups not yet excited.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Generator, Sequence

from mows.device.cycle.phases import CycleOutcome, CyclePlan, CycleRequest, CycleSettings, Phase, TuningFit
from mows.device.cycle.sequencer import CycleSequencer
from mows.device.cycle.tone_groups import GroupExcitation, GroupSequence, on_stage, plan_probes, with_cap
from mows.device.cycle.waits import Answer, Reach, Run
from mows.device.interface import CoilCommand, CommandResult, MultiToneCommand
from mows.physics.coils import CoilSetup, CurrentCap
from mows.physics.coupling import PlacedProbe
from mows.physics.multitone import ExcitationPlan, peak_current_a


class MultiToneSequencer(CycleSequencer):
    """Runs one cycle at a time of the probes ``home`` (at their home orientations, probe id =
    index) on one shared stage, on a device of ``sample_rate_hz`` with the coils of ``setup``;
    ``cap`` the driver's coil current cap, held on every group's summed peak."""

    def __init__(
        self,
        settings: CycleSettings,
        setup: CoilSetup,
        cap: CurrentCap,
        sample_rate_hz: float,
        home: Sequence[PlacedProbe],
        lead_samples: int = 0,
        *,
        fit: TuningFit,
    ):
        if not home:
            raise ValueError("a multi-tone cycle needs its probes")
        super().__init__(settings, setup, cap, sample_rate_hz, home[0].probe.f00_hz, lead_samples, fit=fit)
        self.home = tuple(home)
        self._groups: GroupSequence | None = None

    def excitation(self, theta0_rad: float, settings: CycleSettings) -> ExcitationPlan:
        """The plan of a cycle at stage angle ``theta0_rad``. ValueError, with every probe's
        reason, when it excites none."""
        plan = plan_probes(
            on_stage(self.home, theta0_rad),
            with_cap(self.setup, self.cap.limit_a),
            settings.excite_s,
            tone_limit_a=settings.excitation_current_a,
        )
        if not plan.groups:
            raise ValueError(f"no probe can be excited at θ0 = {theta0_rad:.4g} rad: {refusals(plan)}")
        return plan

    def _plan(self, request: CycleRequest) -> CyclePlan:
        return dataclasses.replace(super()._plan(request), tuning_steps=0)

    def _currents(self, c: CyclePlan) -> tuple:
        """Checks that the cycle's plan excites some probe (ValueError otherwise); a multi-tone
        excitation has no single set of coil currents."""
        self.excitation(c.theta0_rad, c.settings)
        return ()

    def _run(self, c: CyclePlan) -> Run:
        coils_free = yield from self._turn_and_settle(c)
        plan = self.excitation(c.theta0_rad, c.settings)
        recorded = 0
        for k in range(c.repeats):
            groups = self._groups = GroupSequence(
                plan, with_cap(self.setup, self.cap.limit_a), self._duty, self.sample_rate_hz
            )
            while not groups.done:
                gap = self._samples(c.gap_s) if recorded else 0
                excitation = groups.next(max(coils_free + gap, self._next_index + self.lead_samples))
                assert excitation is not None  # not done
                coils_free = yield from self._excite(c, k, groups, excitation, coils_free)
                recorded += 1
        self._groups = None
        yield from self._enter(c, Phase.IDLE, coils_free, 0)
        in_turn = " then ".join(str(list(g)) for g in plan.groups)
        message = f"{recorded} ring-downs recorded of the probes {in_turn} at their f00 (no tuning)"
        if plan.refused:
            message += f"; refused: {refusals(plan)}"
        return CycleOutcome(
            True, message, c.cycle_id, plan.group_tones(0)[0].frequency_hz, recorded, refused_probes=plan.refused
        )

    def _excite(
        self, c: CyclePlan, k: int, groups: GroupSequence, excitation: GroupExcitation, coils_free: int
    ) -> Generator[Answer | Reach, CommandResult | None, int]:
        """Excite the group ``excitation`` of ``groups`` in round ``k`` and record its ring-down,
        announcing GAP (if it waits), EXCITING and RINGDOWN; returns the sample from which the
        coils are free again. The duty limit counts the interval the device applied."""
        samples = excitation.off_index - excitation.on_index
        on = self._issue(MultiToneCommand, excitation.on_index, tones=excitation.tones, samples=samples)
        off = self._issue(
            CoilCommand, excitation.off_index, amplitudes_a=(0.0,) * len(self.setup.coils), frequency_hz=0.0
        )
        if excitation.on_index > coils_free:
            yield from self._enter(c, Phase.GAP, coils_free, excitation.on_index - coils_free, k)
        switched_on = yield from self._answer(on)
        switched_off = yield from self._answer(off)
        groups.switched(switched_on, switched_off)
        peaks = tuple(float(a) for a in peak_current_a(self.setup, excitation.tones, samples / self.sample_rate_hz))
        tones = excitation.tones
        yield from self._enter(
            c, Phase.EXCITING, switched_on, switched_off - switched_on, k, currents=peaks, tones=tones
        )
        ringdown = self._samples(c.settings.ringdown_s)
        yield from self._enter(c, Phase.RINGDOWN, switched_off, ringdown, k, tones=tones)
        yield Reach(switched_off + ringdown)
        return switched_off + ringdown

    def _stop(self, reason: str) -> None:
        """Every tone off now; the groups not yet excited are dropped and the time the coils were
        on counts towards the duty limit."""
        if self._groups is not None and not self._groups.done:
            self._groups.emergency_stop(self._next_index, reason or "stopped")
        self._groups = None
        super()._stop(reason)


def refusals(plan: ExcitationPlan) -> str:
    """The refused probes and their reasons, in one line."""
    return "; ".join(f"probe {probe_id}: {reason}" for probe_id, reason in plan.refused)
