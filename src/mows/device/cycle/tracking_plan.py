"""Tracking mode's plan from the probe's physics, and the drive physics every planned cycle uses.

Excitation. The coils' field b⊥·I, perpendicular to the moment, drives the magnet with the
torque m·b⊥·I·sin(2πft). At resonance the swing grows linearly, θ = r·t·cos(2πft) with
r = m·b⊥·I/(2Jω) (:func:`drive_rate_rad_per_s`), so the shortest drive that reaches the housing
stop is the largest current the cap allows. A swing left over from the previous ring-down adds
to the driven one with an unknown phase: in the worst case it is first driven to zero
(:func:`reach_s`). The drive then goes on for ``LOCK_PERIODS`` periods against the stop, whose
impacts lock the motion to the drive, and a switch-off at the same drive phase starts every
ring-down from the same swing (:func:`excitation_s`; :mod:`mows.sweep.fast_cycle` gives the
measured scatter with and without locking).

Ring-down. One ring-down of length T measures f with at best the Cramér–Rao bound σ_f(T)
(:func:`ringdown_std_model`, with the lever's exact pickup, docs/physics.md §6.7, §11). The
bound is the estimator's (``mows.estimate.ringdown.problem.cramer_rao_frequency_hz``), handed in
by whoever plans (the device layer does not fit), as the sequencer is handed its tuning fit.

Tracking. Kicks and ring-downs at one orientation for B along the axis at a target σ: the
shortest ring-down whose bound meets it, σ_B = σ_f/β0 (Eq. 9), and the kick that refills the
swing (:func:`plan_tracking`), made into the loop's :class:`~mows.device.cycle.tracking.TrackingSettings`
(:func:`tracking_settings`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from mows.device.cycle.tracking import TrackingSettings
from mows.physics.field import MU0_OVER_4PI
from mows.physics.fluxgate import PICKUP_COMBINATIONS, pickup_harmonics
from mows.physics.pose import Pose

EXCITATION_MARGIN = 1.25  # drive this much longer than the worst case needs to reach the stop
LOCK_PERIODS = 6  # drive periods against the stop that lock the motion to the drive
SWITCH_OFF_PHASE = 0.25  # the drive is switched off this fraction of a period past a whole one
# Kicks switched off on reaching the stop start from swings that scatter by 0.64°, which moves
# f by ~0.4 mHz (the gradient spring's amplitude dependence), i.e. ~0.1 µT along the axis:
# tracking targets five times above that need no locking periods.
UNLOCKED_KICK_STD_T = 0.1e-6
MIN_RINGDOWN_PERIODS = 12  # the fit takes ten periods at least, after the recovery
SWEEP_ANGLES_RAD = np.radians(np.arange(0.0, 180.0, 45.0))  # σ_f(θ0 + 180°) ≈ σ_f(θ0)

# (n_samples, sample_rate_hz, f, δ, θmax, φ, θ0, κ, σ, pickup=...) → σ_f, Hz: the Cramér–Rao
# bound of one ring-down (the estimator's cramer_rao_frequency_hz).
RingdownBound = Callable[..., float]
# (θ0 rad, ring-down length s) → σ_f of one ring-down, Hz.
StdModel = Callable[[float, float], float]


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


def kappa_t(pair, pose, moment_am2: float, combine: str = "difference") -> float:
    """κ of Eq. S11 for the pair's combination (μ0·m/4π over r³ or r_eff³, Eq. S10), T."""
    distances = np.linalg.norm(pair.positions_m - np.asarray(pose.magnet_position_m, float), axis=1)
    return float(MU0_OVER_4PI * moment_am2 * (distances**-3.0 @ np.array(PICKUP_COMBINATIONS[combine])))


def ringdown_std_model(
    pair, probe, pose, sample_rate_hz: float, noise_std_t: float, bound: RingdownBound, recovery_s: float
) -> StdModel:
    """σ_f(θ0, T): the Cramér–Rao ``bound`` of one ring-down of length T from the stop at θ0 with
    the lever's exact pickup (:func:`mows.physics.fluxgate.pickup_harmonics`), for white noise
    ``noise_std_t`` per sample of the difference channel (a measured figure), the first
    ``recovery_s`` of each ring-down left out as the fit leaves it out."""
    kappa = kappa_t(pair, pose, probe.moment_am2)
    pickups: dict[float, tuple | None] = {}

    def std_hz(theta0_rad: float, duration_s: float) -> float:
        key = round(float(theta0_rad) % math.tau, 9)
        if key not in pickups:
            pickups[key] = tuple(pickup_harmonics(pair, Pose(theta0_rad=key), probe.lever_m, probe.moment_am2))
        n = int(round((duration_s - recovery_s) * sample_rate_hz))
        return bound(
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
    std_hz: StdModel,
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


def scenario_std_model(scenario, bound: RingdownBound, recovery_s: float, noise_std_t: float | None = None) -> StdModel:
    """:func:`ringdown_std_model` of the device ``scenario`` describes (probe, pose, sensors, sample
    rate). ``noise_std_t``: white σ per sample of the difference channel (a measured figure);
    None: the scenario's noise model's white floor
    (:meth:`mows.physics.fluxgate.NoiseModel.difference_white_std_t`)."""
    fs = scenario.sample_rate_hz
    noise = scenario.noise.difference_white_std_t(fs) if noise_std_t is None else noise_std_t
    if not (noise > 0 and math.isfinite(noise)):
        raise ValueError(f"noise σ {noise!r} T per sample: the bound needs a positive noise figure")
    return ringdown_std_model(scenario.sensors.pair, scenario.probe, scenario.pose, fs, noise, bound, recovery_s)


def tracking_plan(
    scenario, theta0_rad: float, target_std_t: float, current_cap_a: float, std_hz: StdModel, setup=None
) -> TrackingPlan:
    """:func:`plan_tracking` for the device ``scenario`` describes (``setup`` replaces its coils),
    σ_f of a ring-down ``std_hz`` (:func:`scenario_std_model`)."""
    return plan_tracking(
        scenario.probe, setup or scenario.setup, scenario.pose, std_hz, theta0_rad, target_std_t, current_cap_a
    )


def tracking_settings(
    scenario, theta0_rad: float, target_std_t: float, current_a: float, std_hz: StdModel, setup=None
) -> TrackingSettings:
    """Tracking mode's kicks and ring-downs at ``theta0_rad`` from :func:`tracking_plan`, the
    kicks at ``current_a`` (the largest the cap allows: the shortest kick). ValueError when the
    target is out of the physics' reach (the bound of the longest ring-down is in the message)."""
    plan = tracking_plan(scenario, theta0_rad, target_std_t, current_a, std_hz, setup)
    if not plan.feasible:
        raise ValueError(
            f"tracking_target_std_t={target_std_t!r}: below the Cramér–Rao bound of "
            f"the longest ring-down ({plan.bound_std_t:.3g} T in {plan.ringdown_s:.2f} s)"
        )
    return TrackingSettings(theta0_rad, current_a, plan.excite_s, plan.ringdown_s)
