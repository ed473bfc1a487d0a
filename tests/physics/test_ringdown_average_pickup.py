"""The ring-down averaging with the magnet on its lever: which amplitude a constant-frequency
fit's f belongs to depends on where in the swing the signal carries phase, and the exact
pickup (the magnet moving on its lever) has harmonics the far-field Eq. S11 lacks. At
θ0 = 90° the far-field signal is even in the deflection (all at 2f) while the exact one has
a first harmonic too, so the far-field weight misplaces that fit's average.

Requirement: the kernel built from the fit's own pickup series predicts what the lever-aware
estimator reports on a chirped ring-down of the exact dipole pickup to within 2.5 σ of the
fit, at every orientation; the far-field kernel misses it at 90° by more than 10 σ. The chirp
(f falling by 2 % of A²) is ten times the field spring's, so that the averaging dominates the
fit's σ (inflated by the χ² of the unmodelled chirp)."""

import math

import numpy as np
import pytest

from mows.estimate.ringdown import FitOptions, fit_ringdown
from mows.physics import ringdown_average
from mows.physics.fluxgate import dipole_pickup_t
from mows.sim.scenario import load_scenario

SCENARIO = load_scenario("anti_helmholtz")
FS_HZ, SECONDS, DAMPING_PER_S, START_RAD = 20_000.0, 0.5, 1.8, math.radians(24.0)


def law_hz(amplitude_rad):
    return 112.0 * (1.0 - 0.02 * amplitude_rad**2)


def lever_ringdown(theta0_rad):
    """The near − far pickup of the magnet swinging on its lever, chirped by ``law_hz``."""
    t = np.arange(int(SECONDS * FS_HZ)) / FS_HZ
    amplitude = START_RAD * np.exp(-DAMPING_PER_S * t)
    x = amplitude * np.cos(2 * np.pi * np.cumsum(law_hz(amplitude)) / FS_HZ + 0.3)
    probe, pose = SCENARIO.probe, SCENARIO.pose.with_theta0(theta0_rad)
    positions = pose.magnet_position_at(x, probe.lever_m)
    moments = probe.moment_am2 * pose.moment_direction_at(x)
    near, far = SCENARIO.sensors.pair.sensors
    signal = dipole_pickup_t(near, positions, moments) - dipole_pickup_t(far, positions, moments)
    return signal + np.random.default_rng(1).normal(0.0, 1e-4 * np.ptp(signal), signal.size)


def predicted_hz(fit, pickup):
    amplitudes, weights = ringdown_average.amplitude_nodes(
        fit.theta0_rad, START_RAD, DAMPING_PER_S, fit.duration_s, pickup=pickup
    )
    return float((weights * law_hz(amplitudes)).sum())


@pytest.mark.parametrize("theta0_deg", [0.0, 45.0, 90.0, 135.0])
def test_the_fits_own_pickup_places_its_average_and_the_far_field_one_misses_at_90_deg(theta0_deg):
    theta0 = math.radians(theta0_deg)
    options = FitOptions.lever_aware(SCENARIO.sensors.pair, SCENARIO.probe, theta0, max_chi2_dof=math.inf)
    fit = fit_ringdown(lever_ringdown(theta0), FS_HZ, theta0, 112.0, options=options)
    assert fit.ok, fit.report()
    assert len(fit.pickup) == len(options.pickup)
    shift = fit.frequency_hz - law_hz(0.0)
    assert abs(shift) > 100 * fit.frequency_std_hz  # the averaging is what is measured
    assert abs(fit.frequency_hz - predicted_hz(fit, np.asarray(fit.pickup))) < 2.5 * fit.frequency_std_hz
    if theta0_deg == 90.0:
        assert abs(fit.frequency_hz - predicted_hz(fit, None)) > 10 * fit.frequency_std_hz
