"""The measurement cycle from the physics of the probe rather than from habit. The drive's
physics (how fast it grows the swing, how long a kick takes to reach the stop) and σ_f of a
ring-down are the device layer's (:mod:`mows.device.cycle.tracking_plan`, which plans tracking
mode's kicks too); this module plans a sweep's cycle with them and the estimator's bound.

Excitation. The coils' field b⊥·I, perpendicular to the moment, drives the magnet with the
torque m·b⊥·I·sin(2πft). At resonance the swing grows linearly, θ = r·t·cos(2πft) with
r = m·b⊥·I/(2Jω) (the secular solution of J·θ'' + J·ω²·θ = τ·sin ωt), so the shortest drive
that reaches the housing stop is the largest current the cap allows. A swing A_r left over from
the previous ring-down adds to the driven one with an unknown phase: in the worst case it is
first driven to zero, so the stop is reached after at most (θstop + A_r)/r. The drive then
goes on for ``LOCK_PERIODS`` periods against the stop: the impacts (restitution e) lock the
motion to the drive within a few of them, and a switch-off at the same drive phase (a quarter
period past a whole one) starts every ring-down from the same swing. Switched off on first
reaching the stop, the simulated swing scatters by 0.64° (σ over 12 kicks at 10 A); after
11.25 periods by 0.05°. The scatter matters: the lever's gradient spring is ~4 % weaker at 24°
than at small swings, so 0.6° of scatter moves f by ~0.4 mHz, three times the bound of a
ring-down, and a decomposition that pools the swing is biased by it.

Tuning. A drive of duration t_k detuned by Δf gains amplitude at |sinc(π·Δf·t_k)| of the
resonant rate: a short kick is as wide as 1/t_k, far wider than the resonance (δ/π ≈ 0.6 Hz);
once against the stop the impacts lock the motion to the drive, so t_k is the time to reach it.
A separate tuning excitation is needed only when the predicted frequency is uncertain by
more than ``TUNING_PHASE_SLIP``/t_k (a 1.6 % loss of drive); at 10 A (t_k ≈ 40 ms) that is
2.5 Hz, a field of ~0.7 mT.

Ring-down length. One ring-down of length T measures f with at best the Cramér–Rao bound
σ_f(T) (:func:`mows.estimate.ringdown.problem.cramer_rao_frequency_hz`, full model with the
lever-aware pick-up, docs/physics.md §6.7, §11); a cycle costs T plus its overhead (the excitation). The
information per second 1/(σ_f(T)²·(T + overhead)) grows while the swing is large and falls once
it has decayed (~1/δ): its maximum, averaged over the orientations of a sweep, is the length,
but not past ``MAX_DECAY``/δ. The frequency drifts with the decaying swing (docs/physics.md §6.5) and
the decomposition describes a ring-down's frequency by an average over it
(:mod:`mows.physics.ringdown_average`), which holds less well as the swing decays further:
measured on 12-orientation sweeps in the anti-Helmholtz scene with locked 10 A kicks, the
decomposition's χ²/dof was 1.18 with 0.7 s ring-downs and 1.89 with the bound's optimum of
1.15 s, which gave the same σ in 30 % more time.

Gaps. Nothing physical waits between a ring-down and the next excitation: the sensors saturate
during every excitation anyway, and the fit leaves out the coil current's decay and the sensors'
recovery (``recovery_s``) at the start of each ring-down. The coils' duty-cycle limit sets the
only gap: the excitation's share of a cycle must stay within it (the sequencer enforces the limit
in every window as well, by delaying an excitation).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.device.cycle.phases import CycleSettings
from mows.device.cycle.tracking_plan import (
    MIN_RINGDOWN_PERIODS,
    SWEEP_ANGLES_RAD,
    StdModel,
    drive_rate_rad_per_s,
    excitation_s,
    reach_s,
    scenario_std_model,
)
from mows.estimate.ringdown import COIL_OFF_SKIP_S
from mows.estimate.ringdown.problem import cramer_rao_frequency_hz

TUNING_PHASE_SLIP = 0.1  # Δf·t_k above which a detuned kick loses > 1.6 % of its drive
MAX_DECAY = 1.3  # ring-downs end by the time δ·T reaches this (the swing at 27 %)
# The paper's protocol, the habit this module's cycle replaces: at each of 12 orientations two
# tuning excitations and five ring-downs, each a 0.5 s drive and 60 periods of ring-down (at
# 112.5 Hz), 10 s apart.
PAPER_CYCLE = CycleSettings(excite_s=0.5, ringdown_s=60.0 / 112.5, gap_s=10.0, repeats=5, tuning_steps=2)
PAPER_ORIENTATIONS = 12


@dataclasses.dataclass(frozen=True)
class CyclePlan:
    """One cycle's settings (SI units) and the physics they follow from."""

    excitation_current_a: float
    excite_s: float
    ringdown_s: float
    gap_s: float
    tuning_steps: int
    drive_rate_rad_per_s: float  # growth of the swing under the drive at that current
    ringdown_std_hz: float  # Cramér–Rao σ_f of one ring-down at θ0 = 0
    information_per_s: float  # mean over the sweep's orientations of 1/(σ_f²·cycle time), 1/(Hz²·s)

    @property
    def cycle_s(self) -> float:
        """Device time of one repeat: excitation, ring-down, gap."""
        return self.excite_s + self.ringdown_s + self.gap_s


def map_s(settings: CycleSettings, orientations: int) -> float:
    """Device time of one map of ``orientations`` by cycles of ``settings``, without the delays a
    duty-cycle limit may add: at each orientation the settling, every excitation and ring-down
    (tuning ones too) and the gaps between them."""
    excitations = settings.tuning_steps + settings.repeats
    at_one = excitations * (settings.excite_s + settings.ringdown_s) + (excitations - 1) * settings.gap_s
    return orientations * (settings.turn_settle_s + at_one)


def tuning_needed(frequency_uncertainty_hz: float, reach_s_: float) -> bool:
    """Whether a drive that needs ``reach_s_`` to reach the stop needs a tuning excitation first
    (module docstring; once against the stop the impacts lock the motion to the drive)."""
    return abs(frequency_uncertainty_hz) * reach_s_ > TUNING_PHASE_SLIP


def plan_cycle(
    probe,
    setup,
    pose,
    std_hz: StdModel,
    current_cap_a: float,
    max_duty_cycle: float,
    frequency_uncertainty_hz: float = 1.0,
) -> CyclePlan:
    """The cycle that gives the most information per second at the largest current the cap allows.

    ``std_hz(θ0, T)`` is σ_f of one ring-down (:func:`ringdown_std_model`). The information per
    second of a length T, with the excitation its own left-over swing needs and the gap its duty
    cycle needs, rises and then falls: its maximum between 12 periods and ``MAX_DECAY``/δ is
    found by a golden-section search in log T to 1 %."""
    rate = drive_rate_rad_per_s(probe, setup, pose, current_cap_a, probe.f00_hz)

    def residual(duration):
        return probe.theta_stop_rad * math.exp(-probe.damping_per_s * duration)

    def cycle(duration):
        excite = excitation_s(rate, probe.theta_stop_rad, residual(duration), probe.f00_hz)
        gap = max(0.0, excite / max_duty_cycle - excite - duration)
        information = float(np.mean([std_hz(a, duration) ** -2 for a in SWEEP_ANGLES_RAD])) / (excite + duration + gap)
        return information, excite, gap

    low, high = math.log(MIN_RINGDOWN_PERIODS / probe.f00_hz), math.log(MAX_DECAY / max(probe.damping_per_s, 1e-3))
    golden = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = high - golden * (high - low), low + golden * (high - low)
    value_a, value_b = cycle(math.exp(a))[0], cycle(math.exp(b))[0]
    while high - low > 0.01:
        if value_a > value_b:
            high, b, value_b = b, a, value_a
            a = high - golden * (high - low)
            value_a = cycle(math.exp(a))[0]
        else:
            low, a, value_a = a, b, value_b
            b = low + golden * (high - low)
            value_b = cycle(math.exp(b))[0]
    duration = math.exp((low + high) / 2.0)
    information, excite, gap = cycle(duration)
    return CyclePlan(
        excitation_current_a=float(current_cap_a),
        excite_s=float(excite),
        ringdown_s=float(duration),
        gap_s=float(gap),
        tuning_steps=int(
            tuning_needed(frequency_uncertainty_hz, reach_s(rate, probe.theta_stop_rad, residual(duration)))
        ),
        drive_rate_rad_per_s=float(rate),
        ringdown_std_hz=float(std_hz(0.0, duration)),
        information_per_s=information,
    )


def fit_std_model(scenario, noise_std_t: float | None = None) -> StdModel:
    """σ_f(θ0, T) of the estimator's fit at its Cramér–Rao bound on the device ``scenario``
    describes (:func:`mows.device.cycle.tracking_plan.scenario_std_model`; ``noise_std_t`` None:
    the scenario's noise model's white floor)."""
    return scenario_std_model(scenario, cramer_rao_frequency_hz, COIL_OFF_SKIP_S, noise_std_t)


def scenario_cycle_plan(
    scenario, current_cap_a: float, max_duty_cycle: float, noise_std_t: float | None = None
) -> CyclePlan:
    """:func:`plan_cycle` for the device ``scenario`` describes, σ_f from
    :func:`fit_std_model` with ``noise_std_t``."""
    std = fit_std_model(scenario, noise_std_t)
    return plan_cycle(scenario.probe, scenario.setup, scenario.pose, std, current_cap_a, max_duty_cycle)
