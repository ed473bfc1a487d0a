"""What the excitations of a measurement cycle drive and announce, for the sequencer
(:class:`mows.device.cycle.sequencer.CycleSequencer`): the plan of its probes at one stage
angle (:func:`plan_at`, a :class:`StagePlan`) and each group's :class:`Excitation`
(:func:`group_excitation`).

Every probe is driven at its own resonance estimate with the coil setup's orientation-dependent
scheme. How hard follows from whom its tone rings (:func:`mows.device.cycle.tone_groups.rings_others`):

* A tone that rings no other probe of the stage is driven at ``excitation_current_a`` to the
  housing stop (above the cap: the cycle is refused), in a group of its own, cut at its drive's
  turning point, and announces its signed coil currents.
* Tones that ring other probes are sized for a swing, each at most ``excitation_current_a``
  (:func:`mows.device.cycle.tone_groups.swing_tone`), grouped so that each group's summed peak
  stays within the driver's cap, overlapping tones refused with the reason
  (:func:`mows.physics.multitone.plan_excitation`); each group lasts the whole samples of the
  excitation time and announces each coil's summed peak.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from mows.device.cycle.phases import CycleSettings
from mows.device.cycle.tone_groups import GroupExcitation, on_stage, rings_others, swing_tone, with_cap
from mows.device.interface import CoilTone, coil_tones
from mows.physics.coils import CoilSetup, CurrentCap
from mows.physics.coupling import PlacedProbe
from mows.physics.multitone import ExcitationPlan, Tone, peak_current_a, plan_excitation


@dataclasses.dataclass(frozen=True)
class Excitation:
    """One group's excitation, on for samples [``on_index``, ``off_index``): the coil currents it
    announces (driven to the stop: signed per coil; sized for a swing: each coil's summed peak),
    the tones of the probes it rings and each one's θ0, in the same order."""

    on_index: int
    off_index: int
    currents_a: tuple[float, ...]
    tones: tuple[CoilTone, ...]
    theta0_rad: tuple[float, ...]

    @property
    def frequency_hz(self) -> float:
        """The drive's frequency: its first probe's tone."""
        return self.tones[0].frequency_hz


@dataclasses.dataclass(frozen=True)
class StagePlan:
    """The excitation of a cycle's probes at one stage angle: ``plan``'s groups in turn, those of
    the probes in ``to_stop`` each alone and driven to the housing stop (module docstring)."""

    plan: ExcitationPlan
    to_stop: frozenset[int]


def plan_at(
    probes: Sequence[PlacedProbe],
    stage_rad: float,
    setup: CoilSetup,
    cap: CurrentCap,
    settings: CycleSettings,
    frequencies_hz: Sequence[float],
) -> StagePlan:
    """The plan of a cycle of ``probes`` (at their home orientations; probe id = index) at stage
    angle ``stage_rad``, each probe's tone at its entry of ``frequencies_hz`` (module docstring).
    ValueError when a tone driven to the stop is above ``cap`` or when it excites no probe, with
    every probe's reason."""
    placed = on_stage(probes, stage_rad)
    capped = with_cap(setup, cap.limit_a)
    amplitude_a, duration_s = settings.excitation_current_a, settings.excite_s
    alone = frozenset(k for k in range(len(placed)) if not rings_others(k, placed, setup))
    stopped: list[Tone] = []
    shared: list[Tone] = []
    refused: list[tuple[int, str]] = []
    for k, (p, frequency_hz) in enumerate(zip(placed, frequencies_hz, strict=True)):
        if k in alone:
            cap.check(setup.currents_a(p.pose.theta0_rad, amplitude_a))  # ValueError above the cap
            stopped.append(Tone(k, float(frequency_hz), p.pose.theta0_rad, amplitude_a, p.probe.damping_per_s))
            continue
        try:
            shared.append(swing_tone(k, p, capped, frequency_hz, duration_s, tone_limit_a=amplitude_a))
        except ValueError as why:
            refused.append((k, str(why)))
    together = plan_excitation(capped, shared, duration_s)
    plan = ExcitationPlan(
        (*stopped, *together.tones),
        together.duration_s,
        (*((t.probe_id,) for t in stopped), *together.groups),
        (*(f"probe {t.probe_id} rings no other: alone, to the stop" for t in stopped), *together.reasons),
        tuple(sorted(refused + list(together.refused))),
    )
    if not plan.groups:
        raise ValueError(f"no probe can be excited at θ0 = {stage_rad:.4g} rad: {refusals(plan)}")
    return StagePlan(plan, alone)


def group_excitation(setup: CoilSetup, group: GroupExcitation, sample_rate_hz: float, to_stop: bool) -> Excitation:
    """The excitation of a plan's group: its probes' tones, announced by their signed currents
    for a tone driven ``to_stop``, else by each coil's summed peak."""
    tones = coil_tones(setup, group.tones)
    if to_stop:
        currents = tones[0].amplitudes_a
    else:
        duration_s = (group.off_index - group.on_index) / sample_rate_hz
        currents = tuple(float(a) for a in peak_current_a(setup, group.tones, duration_s))
    theta0_rad = tuple(t.theta0_rad for t in group.tones)
    return Excitation(group.on_index, group.off_index, currents, tones, theta0_rad)


def refusals(plan: ExcitationPlan) -> str:
    """The refused probes and their reasons, in one line."""
    return "; ".join(f"probe {probe_id}: {reason}" for probe_id, reason in plan.refused)
