"""Excitation of several probes at once: a multi-tone coil drive, its cap, and which probes may
be excited together.

Each probe k is driven at its own resonance f_k with the single-probe scheme of
:class:`mows.physics.coils.CoilSetup`: coil c carries A_k·sin(θ0_k + φ_c), θ0_k the probe's
orientation. The multi-tone drive is the sum of these waveforms, per coil,

    I_c(t) = Σ_k A_k·sin(θ0_k + φ_c)·sin(2π·f_k·t),   t from switch-on,

so that one tone alone is today's drive exactly. All tones switch on and off together: the
coils are on for one interval per group, whatever the number of tones, and an emergency stop
switches every tone off at once.

The cap bounds the true peak of I_c over the excitation [0, T], not the sum of amplitudes
Σ_k |A_kc|. The sum bounds the peak over unbounded time (tones of incommensurate frequencies
come into phase arbitrarily closely) but the tones start together from zero and the
excitation is finite, so the peak over T can be lower. The peak is found on a grid of step h
and made an upper bound by the grid's interpolation error: between samples, |I_c| exceeds the
sampled maximum by at most h²/8·max|I_c''| ≤ h²/8·Σ_k |A_kc|·ω_k² (the error of linear
interpolation); :func:`peak_current_a` returns that bound, never more than the sum.

Tones that overlap cannot be excited together or in turn: a tone at f_i rings probe j (its
resonance f_j, damping δ_j) too, whether or not probe j's own tone is on. In the rotating-wave
approximation a torque τ·sin(ωt) switched on at t = 0 gives probe j, detuned by
Δω = ω − 2πf_j, the swing amplitude (τ/(2J·ω_j))·|1 − e^{−(δ_j + iΔω)t}|/|δ_j + iΔω|. At the end
of an excitation of duration T it is at most (1 + e^{−δT})/|δ + iΔω| against (1 − e^{−δT})/δ on
resonance, so the cross-talk of equal torques is at most

    ρ(Δω) = δ·(1 + e^{−δT}) / (|δ + iΔω|·(1 − e^{−δT})).

Two tones overlap when ρ exceeds ``max_crosstalk`` for either probe. The separation this
requires is the excitation's spectral width: 1/(π·T·ρ) Hz for δT ≪ 1 (the width of a tone of
duration T), δ/(2π·ρ) for δT ≫ 1 (the probe's resonance width). For the paper's probe
(δ = 1.8 s⁻¹), T = 0.5 s and ρ = 0.1: 6.8 Hz.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from mows.physics.coils import CoilSetup
from mows.physics.coupling import PlacedProbe
from mows.physics.potential import arc_energy_j

#: Probes that share one drive, one scene and one ring-down window, at most: their tones must
#: fit between the fluxgates' band edges at the separations the joint fit resolves.
MAX_PROBES = 4
#: Default largest cross-talk ρ of equal torques between the tones of one drive.
DEFAULT_MAX_CROSSTALK = 0.1
#: The peak's grid margin h²/8·Σ|A|ω² is at most this fraction of Σ|A|.
PEAK_MARGIN_FRACTION = 1e-4


@dataclasses.dataclass(frozen=True)
class Tone:
    """One probe's share of the drive: its resonance, orientation θ0, base current amplitude
    (the single-probe scheme's A) and its damping δ (for the cross-talk rule)."""

    probe_id: int
    frequency_hz: float
    theta0_rad: float
    amplitude_a: float
    damping_per_s: float

    def __post_init__(self) -> None:
        for name in ("frequency_hz", "damping_per_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"tone of probe {self.probe_id}: {name} = {value!r} must be finite and > 0")
        if not math.isfinite(self.theta0_rad):
            raise ValueError(f"tone of probe {self.probe_id}: theta0_rad = {self.theta0_rad!r} must be finite")
        if not (math.isfinite(self.amplitude_a) and self.amplitude_a >= 0.0):
            raise ValueError(f"tone of probe {self.probe_id}: amplitude_a = {self.amplitude_a!r} must be ≥ 0 A")

    @classmethod
    def of(cls, probe_id: int, placed: PlacedProbe, frequency_hz: float, amplitude_a: float) -> Tone:
        """The tone of a placed probe. ValueError if its rotation plane is not the global x–y
        plane, the only one the coil schemes turn their field with (coils.py)."""
        pose = placed.pose
        if not (np.allclose(pose.plane_e1, (1, 0, 0)) and np.allclose(pose.plane_e2, (0, 1, 0))):
            raise ValueError(
                f"probe {probe_id} rotates in the plane {pose.plane_e1}, {pose.plane_e2}: the coil scheme "
                "drives probes in the global x–y plane only"
            )
        return cls(probe_id, float(frequency_hz), pose.theta0_rad, float(amplitude_a), placed.probe.damping_per_s)


def tone_for_swing(
    probe_id: int, placed: PlacedProbe, setup: CoilSetup, frequency_hz: float, swing_rad: float, duration_s: float
) -> Tone:
    """The tone that rings ``placed`` up to about ``swing_rad`` at the end of an excitation of
    ``duration_s`` on resonance: a driven oscillator J·θ'' + 2Jδ·θ' + k·θ = τ·sin ωt swings
    τ·(1 − e^(−δT))/(2J·ω·δ), τ the scheme's torque per ampere of the base amplitude at rest
    (the coils' fields on the magnet's arc, exact). Capped at the setup's limit; ValueError
    if the coils cannot turn this probe (no torque)."""
    probe, pose = placed.probe, placed.pose
    torque_per_a = scheme_torque_nm_per_a(placed, setup, pose.theta0_rad)
    omega, delta = 2.0 * math.pi * frequency_hz, probe.damping_per_s
    gain = (1.0 - math.exp(-delta * duration_s)) / (2.0 * probe.inertia_kgm2 * omega * delta)
    if not torque_per_a * gain > 0.0:
        raise ValueError(f"probe {probe_id}: the coils put no torque on it at θ0 = {pose.theta0_rad:.4g} rad")
    amplitude = min(swing_rad / (torque_per_a * gain), setup.cap.limit_a)
    return Tone(probe_id, float(frequency_hz), pose.theta0_rad, amplitude, delta)


def scheme_torque_nm_per_a(placed: PlacedProbe, setup: CoilSetup, theta0_rad: float) -> float:
    """|τ| on ``placed`` at rest per ampere of base amplitude of ``setup``'s scheme for a probe at
    ``theta0_rad`` (currents sin(θ0 + φ_c) per ampere, unchecked: 1 A may be above a low cap):
    the coils' fields on the magnet's arc, exact."""
    pose = dataclasses.replace(placed.pose, gravity_m_per_s2=(0.0, 0.0, 0.0))
    step_rad = 1e-4
    torques = np.array(
        [
            -np.diff(arc_energy_j(placed.probe, coil, pose, np.array([-step_rad, step_rad])))[0] / (2 * step_rad)
            for coil in setup.coils
        ]
    )
    return abs(float(np.sin(theta0_rad + np.array(setup.phases_rad)) @ torques))


def coil_amplitudes_a(setup: CoilSetup, tones: Sequence[Tone]) -> np.ndarray:
    """(K, n_coils): each tone's signed current amplitude per coil, the single-probe scheme's
    (ValueError if one tone alone is above the cap)."""
    return np.array([setup.currents_a(t.theta0_rad, t.amplitude_a) for t in tones]).reshape(len(tones), -1)


def drive_currents_a(setup: CoilSetup, tones: Sequence[Tone], times_s: ArrayLike) -> np.ndarray:
    """(n, n_coils): the summed current of each coil at ``times_s`` from switch-on, A."""
    times = np.asarray(times_s, float)
    frequencies = np.array([t.frequency_hz for t in tones])
    carriers = np.sin(2.0 * np.pi * times[:, None] * frequencies)  # (n, K)
    return carriers @ coil_amplitudes_a(setup, tones)


def peak_current_a(setup: CoilSetup, tones: Sequence[Tone], duration_s: float) -> np.ndarray:
    """(n_coils,): an upper bound of max |I_c(t)| over [0, ``duration_s``] of ``tones`` driven by
    ``setup``'s scheme (:func:`summed_peak_a`)."""
    return summed_peak_a(coil_amplitudes_a(setup, tones), [t.frequency_hz for t in tones], duration_s)


def summed_peak_a(amplitudes_a: ArrayLike, frequencies_hz: ArrayLike, duration_s: float) -> np.ndarray:
    """(n_coils,): an upper bound of max |I_c(t)| over [0, ``duration_s``] of tones of signed
    coil amplitudes ``amplitudes_a`` (K, n_coils) at ``frequencies_hz`` (K,), within
    PEAK_MARGIN_FRACTION of the true peak (module docstring), never above Σ_k |A_kc|, which it
    is for an unbounded drive (``duration_s`` infinite: the tones come into phase)."""
    if not (duration_s > 0.0):
        raise ValueError(f"duration_s = {duration_s!r} must be > 0")
    amplitudes = np.abs(np.asarray(amplitudes_a, float))  # (K, n_coils)
    if math.isinf(duration_s):
        return amplitudes.sum(axis=0)
    omegas = 2.0 * np.pi * np.asarray(frequencies_hz, float)
    step_s = math.sqrt(8.0 * PEAK_MARGIN_FRACTION) / omegas.max()
    times = np.linspace(0.0, duration_s, int(math.ceil(duration_s / step_s)) + 1)
    h = times[1] - times[0]
    carriers = np.sin(times[:, None] * omegas)  # (n, K)
    sampled = np.abs(carriers @ np.asarray(amplitudes_a, float)).max(axis=0)
    margin = h * h / 8.0 * (omegas**2 @ amplitudes)
    return np.minimum(sampled + margin, amplitudes.sum(axis=0))


def crosstalk(detuning_hz: float, damping_per_s: float, duration_s: float) -> float:
    """ρ of the module docstring: the largest swing a tone ``detuning_hz`` off a probe's
    resonance gives it at the end of an excitation of ``duration_s``, per swing of an equal
    torque on resonance."""
    decay = math.exp(-damping_per_s * duration_s)
    distance = math.hypot(damping_per_s, 2.0 * math.pi * detuning_hz)
    return damping_per_s * (1.0 + decay) / (distance * (1.0 - decay))


def required_separation_hz(damping_per_s: float, duration_s: float, max_crosstalk: float) -> float:
    """The least detuning at which :func:`crosstalk` is ``max_crosstalk``, Hz (the excitation's
    spectral width for that cross-talk)."""
    decay = math.exp(-damping_per_s * duration_s)
    distance = damping_per_s * (1.0 + decay) / ((1.0 - decay) * max_crosstalk)
    return math.sqrt(max(distance**2 - damping_per_s**2, 0.0)) / (2.0 * math.pi)


@dataclasses.dataclass(frozen=True)
class ExcitationPlan:
    """Which probes are excited together and why: ``groups`` of probe ids, excited in turn,
    ``reasons`` one line per group; ``refused`` (probe id, reason) of probes not excited."""

    tones: tuple[Tone, ...]
    duration_s: float
    groups: tuple[tuple[int, ...], ...]
    reasons: tuple[str, ...]
    refused: tuple[tuple[int, str], ...]

    def group_tones(self, index: int) -> tuple[Tone, ...]:
        members = self.groups[index]
        return tuple(t for t in self.tones if t.probe_id in members)


def plan_excitation(
    setup: CoilSetup,
    tones: Sequence[Tone],
    duration_s: float,
    max_crosstalk: float = DEFAULT_MAX_CROSSTALK,
) -> ExcitationPlan:
    """Group ``tones`` (in order: earlier tones take precedence) for excitations of
    ``duration_s``. A tone is refused if it alone exceeds the cap, or if it overlaps an
    accepted tone (cross-talk above ``max_crosstalk``, module docstring): exciting either
    would ring both. The others join the first group whose summed peak stays within the cap,
    or open a new group, excited after the ones before."""
    if not (math.isfinite(duration_s) and duration_s > 0.0):
        raise ValueError(f"duration_s = {duration_s!r} must be finite and > 0")
    if not (math.isfinite(max_crosstalk) and 0.0 < max_crosstalk < 1.0):
        raise ValueError(f"max_crosstalk = {max_crosstalk!r} must be in (0, 1)")
    ids = [t.probe_id for t in tones]
    if len(set(ids)) != len(ids):
        raise ValueError(f"probe ids {ids} must be distinct")
    accepted: list[Tone] = []
    refused: list[tuple[int, str]] = []
    for tone in tones:
        reason = _refusal(setup, tone, accepted, duration_s, max_crosstalk)
        if reason:
            refused.append((tone.probe_id, reason))
        else:
            accepted.append(tone)
    groups: list[list[Tone]] = []
    reasons: list[str] = []
    limit_a = setup.cap.limit_a
    for tone in accepted:
        for group in groups:
            if peak_current_a(setup, [*group, tone], duration_s).max() <= limit_a:
                group.append(tone)
                break
        else:
            if groups:
                peak = min(peak_current_a(setup, [*g, tone], duration_s).max() for g in groups)
                reasons.append(
                    f"probe {tone.probe_id} with any group before would peak at ≥ {peak:.4g} A "
                    f"> the {limit_a:g} A cap: excited after them"
                )
            else:
                reasons.append(f"probe {tone.probe_id} first")
            groups.append([tone])
    for k, group in enumerate(groups):
        peak = peak_current_a(setup, group, duration_s).max()
        reasons[k] += f"; group {k + 1} {[t.probe_id for t in group]} peaks at {peak:.4g} A ≤ {limit_a:g} A"
    return ExcitationPlan(
        tuple(tones),
        float(duration_s),
        tuple(tuple(t.probe_id for t in g) for g in groups),
        tuple(reasons),
        tuple(refused),
    )


def _refusal(setup: CoilSetup, tone: Tone, accepted: Sequence[Tone], duration_s: float, max_crosstalk: float) -> str:
    """Why ``tone`` cannot be excited beside ``accepted``, '' if it can."""
    try:
        coil_amplitudes_a(setup, [tone])
    except ValueError as error:
        return f"alone above the cap: {error}"
    for other in accepted:
        detuning_hz = tone.frequency_hz - other.frequency_hz
        for probe in (tone, other):
            rho = crosstalk(detuning_hz, probe.damping_per_s, duration_s)
            if rho > max_crosstalk:
                need_hz = required_separation_hz(probe.damping_per_s, duration_s, max_crosstalk)
                return (
                    f"{abs(detuning_hz):.3g} Hz from probe {other.probe_id}, closer than the {need_hz:.3g} Hz "
                    f"the {duration_s:g} s excitation needs (cross-talk {rho:.2f} > {max_crosstalk:g} on "
                    f"probe {probe.probe_id}): exciting either would ring both"
                )
    return ""
