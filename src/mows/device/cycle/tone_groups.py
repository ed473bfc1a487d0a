"""The groups of an excitation plan (:func:`mows.physics.multitone.plan_excitation`) excited in
turn on the device clock, under the coils' duty-cycle limit and the emergency stop.

A group's tones switch on and off together, so the coils are on for one interval per group:
the duty limit (:class:`mows.device.cycle.duty.DutyCycleLimit`) counts that interval once, whatever
the number of tones summed in it. A group is delayed, never shortened, until its interval
keeps the limit. An excitation lasts the whole samples within the plan's duration, the span
whose summed peak the plan checked against the cap. An emergency stop switches every tone off
at its sample, drops the groups not yet excited and latches: nothing more is excited.

I/O-free: fed the sample a group may start at, the interval the device applied and the stop;
it returns the excitations to command and the summed coil currents at given samples.

A tone that rings other probes of the stage (:func:`rings_others`) is sized for a swing
(:func:`swing_tone`, :func:`mows.physics.multitone.tone_for_swing`), at most a given current;
:func:`plan_probes` plans a stage's probes so at their f00, grouped under the cap with the
overlapping tones refused. The group of a tone driven to the stop is cut at its drive's turning
point instead (:mod:`mows.device.cycle.excitation`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from mows.device.cycle.duty import DutyCycleLimit
from mows.physics.coils import CoilSetup, CurrentCap, excitation_samples
from mows.physics.coupling import PlacedProbe
from mows.physics.multitone import (
    ExcitationPlan,
    Tone,
    drive_currents_a,
    plan_excitation,
    scheme_torque_nm_per_a,
    summed_peak_a,
    tone_for_swing,
)

#: The swing each probe's tone aims at the end of its excitation, rad.
DEFAULT_SWING_RAD = 0.15


def on_stage(home: Sequence[PlacedProbe], stage_rad: float) -> list[PlacedProbe]:
    """The probes of one shared stage turned by ``stage_rad`` from their home orientations."""
    return [dataclasses.replace(p, pose=p.pose.with_theta0(p.pose.theta0_rad + stage_rad)) for p in home]


def plan_probes(
    placed: Sequence[PlacedProbe],
    setup: CoilSetup,
    duration_s: float,
    swing_rad: float = DEFAULT_SWING_RAD,
    tone_limit_a: float = math.inf,
) -> ExcitationPlan:
    """The excitation plan of ``placed`` (probe id = index) for excitations of ``duration_s``
    under ``setup``'s cap: each tone at its probe's f00 (:func:`swing_tone`), the refused with
    the reason."""
    tones, refused = [], []
    for k, p in enumerate(placed):
        try:
            tones.append(swing_tone(k, p, setup, p.probe.f00_hz, duration_s, swing_rad, tone_limit_a))
        except ValueError as why:
            refused.append((k, str(why)))
    plan = plan_excitation(setup, tones, duration_s)
    return dataclasses.replace(plan, refused=tuple(sorted(refused + list(plan.refused))))


def swing_tone(
    probe_id: int,
    placed: PlacedProbe,
    setup: CoilSetup,
    frequency_hz: float,
    duration_s: float,
    swing_rad: float = DEFAULT_SWING_RAD,
    tone_limit_a: float = math.inf,
) -> Tone:
    """The tone of ``placed`` at ``frequency_hz`` for ``swing_rad`` after ``duration_s``
    (:func:`mows.physics.multitone.tone_for_swing`), its amplitude at most ``tone_limit_a``.
    ValueError, with the reason, for a probe the coils put no torque on or whose tone
    ``tone_limit_a`` leaves at zero."""
    tone = tone_for_swing(probe_id, placed, setup, frequency_hz, swing_rad, duration_s)
    amplitude_a = min(tone.amplitude_a, tone_limit_a)
    if not amplitude_a > 0.0:
        raise ValueError(f"a tone of at most {tone_limit_a:g} A excites nothing")
    return dataclasses.replace(tone, amplitude_a=amplitude_a)


def rings_others(probe_id: int, placed: Sequence[PlacedProbe], setup: CoilSetup) -> bool:
    """Whether the tone of ``placed[probe_id]`` (``setup``'s scheme at its θ0) puts a torque on
    another probe of the stage: any at all, as a tone driven to the housing stop rings a
    neighbour far above the swing its own tone gives it."""
    theta0_rad = placed[probe_id].pose.theta0_rad
    return any(scheme_torque_nm_per_a(p, setup, theta0_rad) > 0.0 for k, p in enumerate(placed) if k != probe_id)


def with_cap(setup: CoilSetup, limit_a: float) -> CoilSetup:
    """``setup`` under the lower of its own cap and ``limit_a``."""
    return dataclasses.replace(setup, cap=CurrentCap(min(setup.cap.limit_a, limit_a)))


@dataclasses.dataclass(frozen=True)
class GroupExcitation:
    """One group's excitation: its tones, on for samples [``on_index``, ``off_index``)."""

    group_index: int
    tones: tuple[Tone, ...]
    on_index: int
    off_index: int

    @property
    def probe_ids(self) -> tuple[int, ...]:
        return tuple(t.probe_id for t in self.tones)


class GroupSequence:
    """Excites the groups of ``plan`` in turn with the coils of ``setup`` (module docstring); the
    group of a probe in ``to_stop`` (driven to the housing stop, alone) is cut at its drive's
    turning point (:func:`mows.physics.coils.excitation_samples`).

    ValueError if a group's summed peak is above the setup's cap or its excitation could never
    keep the duty limit ``duty``.
    """

    def __init__(
        self,
        plan: ExcitationPlan,
        setup: CoilSetup,
        duty: DutyCycleLimit,
        sample_rate_hz: float,
        to_stop: frozenset[int] = frozenset(),
    ):
        if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0.0):
            raise ValueError(f"sample_rate_hz = {sample_rate_hz!r} must be finite and > 0")
        self.setup = setup
        self.sample_rate_hz = float(sample_rate_hz)
        self.excite_samples = math.floor(plan.duration_s * sample_rate_hz)
        self._groups = [plan.group_tones(k) for k in range(len(plan.groups))]
        self._samples = [
            excitation_samples(plan.duration_s, tones[0].frequency_hz, sample_rate_hz)
            if tones[0].probe_id in to_stop
            else self.excite_samples
            for tones in self._groups
        ]
        phases = np.array(setup.phases_rad)
        for k, tones in enumerate(self._groups):
            # Each coil's true peak, the amplitude of a tone driven to the stop may be above the cap.
            amplitudes = [t.amplitude_a * np.sin(t.theta0_rad + phases) for t in tones]
            peak = summed_peak_a(amplitudes, [t.frequency_hz for t in tones], plan.duration_s).max()
            if peak > setup.cap.limit_a:
                raise ValueError(f"group {k + 1} peaks at {peak:.6g} A, above the {setup.cap.limit_a:g} A cap")
        for samples in self._samples:
            duty.earliest_start(0, samples)  # ValueError if it never fits
        self._duty = duty
        self.excitations: list[GroupExcitation] = []
        self.stop_reason = ""  # the latched emergency stop's reason, '' while none
        self._stop_index: int | None = None
        self._recorded = 0  # excitations whose interval the duty limit holds

    @property
    def done(self) -> bool:
        return bool(self.stop_reason) or len(self.excitations) == len(self._groups)

    def next(self, not_before: int) -> GroupExcitation | None:
        """The next group's excitation, at the first sample ≥ ``not_before`` that keeps the
        duty limit; None when every group was excited or a stop latched."""
        if self.done:
            return None
        if self._recorded < len(self.excitations):
            raise ValueError("the previous excitation's applied interval was not reported (switched)")
        k = len(self.excitations)
        start = self._duty.earliest_start(int(not_before), self._samples[k])
        excitation = GroupExcitation(k, self._groups[k], start, start + self._samples[k])
        self.excitations.append(excitation)
        return excitation

    def switched(self, on_index: int, off_index: int) -> None:
        """The device applied the last excitation over [``on_index``, ``off_index``)."""
        self._duty.record(on_index, off_index)
        self._recorded = len(self.excitations)

    def emergency_stop(self, at_index: int, reason: str) -> None:
        """Every tone off from sample ``at_index`` on; the groups not yet excited are dropped."""
        if not reason:
            raise ValueError("an emergency stop needs its reason")
        self.stop_reason = reason
        self._stop_index = int(at_index)
        if self._recorded < len(self.excitations):
            last = self.excitations[-1]
            self.switched(last.on_index, max(last.on_index, min(last.off_index, self._stop_index)))

    def currents_a(self, sample_indices: ArrayLike) -> np.ndarray:
        """(n, n_coils): the summed coil currents at ``sample_indices``, zero outside the
        excitations and from an emergency stop on."""
        index = np.asarray(sample_indices, dtype=np.int64)
        currents = np.zeros((index.size, len(self.setup.coils)))
        for e in self.excitations:
            off = e.off_index if self._stop_index is None else min(e.off_index, self._stop_index)
            on = (index >= e.on_index) & (index < off)
            currents[on] = drive_currents_a(self.setup, e.tones, (index[on] - e.on_index) / self.sample_rate_hz)
        return currents
