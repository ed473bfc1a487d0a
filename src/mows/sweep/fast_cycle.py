"""The measurement cycle from the physics of the probe rather than from habit.

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
from collections.abc import Callable

import numpy as np

from mows.device.cycle.phases import CycleSettings
from mows.device.cycle.tracking import TrackingSettings
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions
from mows.estimate.ringdown.problem import cramer_rao_frequency_hz
from mows.physics.field import MU0_OVER_4PI
from mows.physics.fluxgate import PICKUP_COMBINATIONS

TUNING_PHASE_SLIP = 0.1  # Δf·t_k above which a detuned kick loses > 1.6 % of its drive
EXCITATION_MARGIN = 1.25  # drive this much longer than the worst case needs to reach the stop
LOCK_PERIODS = 6  # drive periods against the stop that lock the motion to the drive
SWITCH_OFF_PHASE = 0.25  # the drive is switched off this fraction of a period past a whole one
MAX_DECAY = 1.3  # ring-downs end by the time δ·T reaches this (the swing at 27 %)
# Kicks switched off on reaching the stop start from swings that scatter by 0.64°, which moves
# f by ~0.4 mHz (the gradient spring's amplitude dependence), i.e. ~0.1 µT along the axis:
# tracking targets five times above that need no locking periods.
UNLOCKED_KICK_STD_T = 0.1e-6
MIN_RINGDOWN_PERIODS = 12  # the fit takes ten periods at least, after the recovery
SWEEP_ANGLES_RAD = np.radians(np.arange(0.0, 180.0, 45.0))  # σ_f(θ0 + 180°) ≈ σ_f(θ0)
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


def drive_rate_rad_per_s(probe, setup, pose, current_a: float, frequency_hz: float) -> float:
    """r = m·b⊥·I/(2Jω): how fast a resonant drive of base amplitude ``current_a`` grows the
    swing, rad/s, at the weakest of the sweep's orientations (``pose`` gives the magnet's place)."""
    weakest = math.inf
    for theta0 in SWEEP_ANGLES_RAD:
        at = pose.with_theta0(theta0)
        field = setup.field_t(np.asarray(at.magnet_position_m, float), setup.currents_a(theta0, current_a))
        weakest = min(weakest, abs(float(np.asarray(field).reshape(3) @ at.axes()[1])))
    return probe.moment_am2 * weakest / (2.0 * probe.inertia_kgm2 * math.tau * frequency_hz)


def excitation_s(
    rate_rad_per_s: float, stop_rad: float, residual_rad: float, frequency_hz: float, lock_periods: int = LOCK_PERIODS
) -> float:
    """Drive time that reaches the stop from a left-over swing ``residual_rad`` in any phase,
    then locks the motion to the drive for ``lock_periods`` and ends at the same drive phase
    (module docstring)."""
    reach = reach_s(rate_rad_per_s, stop_rad, residual_rad)
    return (math.ceil(reach * frequency_hz) + lock_periods + SWITCH_OFF_PHASE) / frequency_hz


def reach_s(rate_rad_per_s: float, stop_rad: float, residual_rad: float) -> float:
    """Drive time to the stop from a left-over swing in any phase, with ``EXCITATION_MARGIN``."""
    if not (rate_rad_per_s > 0 and math.isfinite(rate_rad_per_s)):
        raise ValueError(f"drive rate {rate_rad_per_s!r} rad/s: the coils cannot drive the probe")
    return EXCITATION_MARGIN * (stop_rad + abs(residual_rad)) / rate_rad_per_s


def tuning_needed(frequency_uncertainty_hz: float, reach_s_: float) -> bool:
    """Whether a drive that needs ``reach_s_`` to reach the stop needs a tuning excitation first
    (module docstring; once against the stop the impacts lock the motion to the drive)."""
    return abs(frequency_uncertainty_hz) * reach_s_ > TUNING_PHASE_SLIP


def kappa_t(pair, pose, moment_am2: float, combine: str = "difference") -> float:
    """κ of Eq. S11 for the pair's combination (μ0·m/4π over r³ or r_eff³, Eq. S10), T."""
    distances = np.linalg.norm(pair.positions_m - np.asarray(pose.magnet_position_m, float), axis=1)
    return float(MU0_OVER_4PI * moment_am2 * (distances**-3.0 @ np.array(PICKUP_COMBINATIONS[combine])))


def ringdown_std_model(
    pair, probe, pose, sample_rate_hz: float, noise_std_t: float, recovery_s: float = COIL_OFF_SKIP_S
) -> Callable[[float, float], float]:
    """σ_f(θ0, T): the Cramér–Rao bound of one ring-down of length T from the stop at θ0, for
    white noise ``noise_std_t`` per sample of the difference channel (a measured figure)."""
    kappa = kappa_t(pair, pose, probe.moment_am2)
    pickups: dict[float, tuple | None] = {}

    def std_hz(theta0_rad: float, duration_s: float) -> float:
        key = round(float(theta0_rad) % math.tau, 9)
        if key not in pickups:
            pickups[key] = FitOptions.lever_aware(pair, probe, key).pickup
        n = int(round((duration_s - recovery_s) * sample_rate_hz))
        return cramer_rao_frequency_hz(
            n,
            sample_rate_hz,
            probe.f00_hz,
            probe.damping_per_s,
            probe.theta_stop_rad,
            0.0,
            key,
            kappa,
            noise_std_t,
            pickup=pickups[key],
        )

    return std_hz


def plan_cycle(
    probe,
    setup,
    pose,
    std_hz: Callable[[float, float], float],
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


@dataclasses.dataclass(frozen=True)
class TrackingPlan:
    """Kicks and ring-downs at one orientation for B along the probe axis at σ ≤ ``target_std_t``:
    the shortest ring-down whose Cramér–Rao bound meets it (``bound_std_t``), and the kick that
    refills the swing. ``feasible`` is False when no ring-down up to 3/δ meets the target; the
    bound at 3/δ is then reported."""

    target_std_t: float
    feasible: bool
    excite_s: float
    ringdown_s: float
    bound_std_t: float

    @property
    def updates_per_s(self) -> float:
        return 1.0 / (self.excite_s + self.ringdown_s)


def plan_tracking(
    probe,
    setup,
    pose,
    std_hz: Callable[[float, float], float],
    theta0_rad: float,
    target_std_t: float,
    current_cap_a: float,
) -> TrackingPlan:
    """The fastest updates of B along the axis at θ0 that the bound allows for ``target_std_t``.
    σ_B = σ_f/β0 (Eq. 9); the ring-down length is found by bisection in log T to 0.1 %. Kicks
    lock onto the drive only for targets below 5 × ``UNLOCKED_KICK_STD_T``."""
    beta = probe.beta0_hz_per_t
    low, high = MIN_RINGDOWN_PERIODS / probe.f00_hz, 3.0 / max(probe.damping_per_s, 1e-3)
    rate = drive_rate_rad_per_s(probe, setup, pose, current_cap_a, probe.f00_hz)
    lock = 0 if target_std_t >= 5.0 * UNLOCKED_KICK_STD_T else LOCK_PERIODS

    def kick(duration):
        return excitation_s(
            rate,
            probe.theta_stop_rad,
            probe.theta_stop_rad * math.exp(-probe.damping_per_s * duration),
            probe.f00_hz,
            lock,
        )

    if std_hz(theta0_rad, high) / beta > target_std_t:
        return TrackingPlan(target_std_t, False, kick(high), high, std_hz(theta0_rad, high) / beta)
    if std_hz(theta0_rad, low) / beta > target_std_t:
        while math.log(high / low) > 1e-3:
            middle = math.sqrt(low * high)
            low, high = (low, middle) if std_hz(theta0_rad, middle) / beta <= target_std_t else (middle, high)
    else:
        high = low  # the shortest ring-down the fit takes already meets it
    return TrackingPlan(target_std_t, True, kick(high), high, std_hz(theta0_rad, high) / beta)


def scenario_std_model(scenario, noise_std_t: float | None = None) -> Callable[[float, float], float]:
    """:func:`ringdown_std_model` of the device ``scenario`` describes (probe, pose, sensors, sample
    rate). ``noise_std_t``: white σ per sample of the difference channel (a measured figure);
    None: the scenario's noise model's white floor
    (:meth:`mows.physics.fluxgate.NoiseModel.difference_white_std_t`)."""
    fs = scenario.sample_rate_hz
    noise = scenario.noise.difference_white_std_t(fs) if noise_std_t is None else noise_std_t
    if not (noise > 0 and math.isfinite(noise)):
        raise ValueError(f"noise σ {noise!r} T per sample: the bound needs a positive noise figure")
    return ringdown_std_model(scenario.sensors.pair, scenario.probe, scenario.pose, fs, noise)


def scenario_cycle_plan(
    scenario, current_cap_a: float, max_duty_cycle: float, noise_std_t: float | None = None
) -> CyclePlan:
    """:func:`plan_cycle` for the device ``scenario`` describes, σ_f from
    :func:`scenario_std_model` with ``noise_std_t``."""
    std = scenario_std_model(scenario, noise_std_t)
    return plan_cycle(scenario.probe, scenario.setup, scenario.pose, std, current_cap_a, max_duty_cycle)


def tracking_plan(
    scenario, theta0_rad: float, target_std_t: float, current_cap_a: float, noise_std_t: float | None = None, setup=None
) -> TrackingPlan:
    """:func:`plan_tracking` for the device ``scenario`` describes (``setup`` replaces its coils),
    σ_f from :func:`scenario_std_model` with ``noise_std_t``."""
    std = scenario_std_model(scenario, noise_std_t)
    return plan_tracking(
        scenario.probe, setup or scenario.setup, scenario.pose, std, theta0_rad, target_std_t, current_cap_a
    )


def tracking_settings(
    scenario, theta0_rad: float, target_std_t: float, current_a: float, noise_std_t: float | None = None, setup=None
) -> TrackingSettings:
    """Tracking mode's kicks and ring-downs at ``theta0_rad`` from :func:`tracking_plan`, the
    kicks at ``current_a`` (the largest the cap allows: the shortest kick). ValueError when the
    target is out of the physics' reach (the bound of the longest ring-down is in the message)."""
    plan = tracking_plan(scenario, theta0_rad, target_std_t, current_a, noise_std_t, setup)
    if not plan.feasible:
        raise ValueError(
            f"tracking_target_std_t={target_std_t!r}: below the Cramér–Rao bound of "
            f"the longest ring-down ({plan.bound_std_t:.3g} T in {plan.ringdown_s:.2f} s)"
        )
    return TrackingSettings(theta0_rad, current_a, plan.excite_s, plan.ringdown_s)
