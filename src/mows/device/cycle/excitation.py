"""What one excitation of a measurement cycle drives and announces (:class:`Excitation`), for
the sequencer (:class:`mows.device.cycle.sequencer.CycleSequencer`): one probe driven with the
coil setup's currents at its θ0, a tone of one (:func:`probe_excitation`), or a group of the
plan of several probes at one stage angle (:func:`plan_at`, :func:`group_excitation`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from mows.device.cycle.phases import CycleSettings
from mows.device.cycle.tone_groups import GroupExcitation, on_stage, plan_probes
from mows.device.interface import CoilTone, coil_tones
from mows.physics.coils import CoilSetup, CurrentCap
from mows.physics.coupling import PlacedProbe
from mows.physics.multitone import ExcitationPlan, peak_current_a


@dataclasses.dataclass(frozen=True)
class Excitation:
    """One group's excitation, on for samples [``on_index``, ``off_index``): the coil currents it
    announces (one probe: signed per coil; several: each coil's summed peak), the tones of the
    probes it rings (one probe's a tone of one) and each one's θ0, in the same order."""

    on_index: int
    off_index: int
    currents_a: tuple[float, ...]
    tones: tuple[CoilTone, ...]
    theta0_rad: tuple[float, ...]

    @property
    def frequency_hz(self) -> float:
        """The drive's frequency: its first probe's tone."""
        return self.tones[0].frequency_hz


def probe_currents(setup: CoilSetup, cap: CurrentCap, theta0_rad: float, amplitude_a: float) -> tuple[float, ...]:
    """One probe's coil currents at ``theta0_rad`` in ``setup``'s scheme, checked against ``cap``
    (ValueError above it)."""
    return tuple(float(i) for i in cap.check(setup.currents_a(theta0_rad, amplitude_a)))


def probe_excitation(
    setup: CoilSetup,
    cap: CurrentCap,
    theta0_rad: float,
    amplitude_a: float,
    frequency_hz: float,
    on_index: int,
    samples: int,
) -> Excitation:
    """One probe's excitation (probe 0) at ``frequency_hz`` for ``samples`` from ``on_index``."""
    currents = probe_currents(setup, cap, theta0_rad, amplitude_a)
    tone = CoilTone(0, float(frequency_hz), currents)
    return Excitation(on_index, on_index + samples, currents, (tone,), (float(theta0_rad),))


def plan_at(
    probes: Sequence[PlacedProbe], theta0_rad: float, capped_setup: CoilSetup, settings: CycleSettings
) -> ExcitationPlan:
    """The plan of a cycle of ``probes`` (at their home orientations) at stage angle
    ``theta0_rad``, under the cap of ``capped_setup``. ValueError, with every probe's reason,
    when it excites none."""
    plan = plan_probes(
        on_stage(probes, theta0_rad), capped_setup, settings.excite_s, tone_limit_a=settings.excitation_current_a
    )
    if not plan.groups:
        raise ValueError(f"no probe can be excited at θ0 = {theta0_rad:.4g} rad: {refusals(plan)}")
    return plan


def group_excitation(setup: CoilSetup, group: GroupExcitation, sample_rate_hz: float) -> Excitation:
    """The excitation of a plan's group: its probes' tones, announced by each coil's summed peak."""
    duration_s = (group.off_index - group.on_index) / sample_rate_hz
    peaks = tuple(float(a) for a in peak_current_a(setup, group.tones, duration_s))
    theta0_rad = tuple(t.theta0_rad for t in group.tones)
    return Excitation(group.on_index, group.off_index, peaks, coil_tones(setup, group.tones), theta0_rad)


def refusals(plan: ExcitationPlan) -> str:
    """The refused probes and their reasons, in one line."""
    return "; ".join(f"probe {probe_id}: {reason}" for probe_id, reason in plan.refused)
