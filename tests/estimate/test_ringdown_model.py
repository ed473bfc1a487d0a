"""The fit's model, its Fisher information and its options, against independent computations."""

import math

import numpy as np
import pytest

from mows.bench.estimator import (
    AMPLITUDE_RAD,
    DAMPING_PER_S,
    FREQUENCY_HZ,
    KAPPA_T,
    N_SAMPLES,
    OFFSET_T,
    PHASE_RAD,
    SAMPLE_RATE_HZ,
    reference_crb_hz,
)
from mows.estimate.axis import estimate_along_axis
from mows.estimate.ringdown import FitOptions, fit_ringdown
from mows.physics.fluxgate import NoiseModel
from mows.physics.frequency import frequency_shift_hz
from mows.physics.probe import PAPER_PROBE
from mows.physics.signal import signal_t
from mows.sim.noise import NoiseStream

T = np.arange(N_SAMPLES) / SAMPLE_RATE_HZ
TRUTH = {
    "frequency_hz": FREQUENCY_HZ,
    "damping_per_s": DAMPING_PER_S,
    "amplitude_rad": AMPLITUDE_RAD,
    "phase_rad": PHASE_RAD,
    "kappa_t": KAPPA_T,
    "offset_t": OFFSET_T,
    "rest_offset_rad": 0.0,
}


def clean(theta0, a=0.0, b=1.0, kappa=KAPPA_T):
    return signal_t(
        T, theta0, AMPLITUDE_RAD, FREQUENCY_HZ, PHASE_RAD, DAMPING_PER_S, kappa, a=a, b=b, offset_t=OFFSET_T
    )


@pytest.mark.parametrize("theta0_deg, direction", [(0.0, (0.0, 1.0)), (60.0, (0.0, 1.0)), (40.0, (0.6, 0.8))])
def test_crb_equals_fisher_of_the_printed_model(theta0_deg, direction):
    # Differentiate Eq. S11 (mows.physics.signal.signal_t) numerically over all seven parameters
    # (the rest offset ε turns θ0) and invert the Fisher matrix: the analytic Jacobian of the fit
    # must give the same bound.
    theta0, sigma = math.radians(theta0_deg), 1e-9
    names = ["frequency_hz", "damping_per_s", "amplitude_rad", "phase_rad", "kappa_t", "offset_t", "rest_offset_rad"]
    base = np.array([TRUTH[k] for k in names])
    steps = np.array([1e-6, 1e-6, 1e-7, 1e-7, 1e-13, 1e-13, 1e-7])

    def model(p):
        return signal_t(T, theta0 + p[6], p[2], p[0], p[3], p[1], p[4], a=direction[0], b=direction[1], offset_t=p[5])

    jac = np.stack(
        [
            (model(base + np.eye(7)[i] * steps[i]) - model(base - np.eye(7)[i] * steps[i])) / (2 * steps[i])
            for i in range(7)
        ],
        axis=1,
    )
    scale = np.sqrt(np.diag(jac.T @ jac))
    numeric = sigma * math.sqrt(np.linalg.inv((jac / scale).T @ (jac / scale))[0, 0]) / scale[0]
    analytic = reference_crb_hz(theta0, sigma, sensor_direction=direction)
    assert analytic == pytest.approx(numeric, rel=1e-5)


def pull(fit, name, truth):
    index = fit.parameter_names.index(name)
    return (getattr(fit, name) - truth) / math.sqrt(fit.covariance[index, index])


def test_every_parameter_is_recovered_within_its_uncertainty():
    rng = np.random.default_rng(11)
    sigma = 2e-10
    fit = fit_ringdown(
        clean(math.radians(40)) + sigma * rng.standard_normal(N_SAMPLES), SAMPLE_RATE_HZ, math.radians(40), 112.0
    )
    assert fit.ok, fit.message
    for name, truth in TRUTH.items():
        if name in fit.undetermined:  # not pinned to its tolerance: NaN, the reason said
            assert math.isnan(getattr(fit, name)) and "not determined" in fit.message
            continue
        assert abs(pull(fit, name, truth)) < 4, name
    assert fit.chi2_dof == pytest.approx(1.0, abs=5 * math.sqrt(2 / N_SAMPLES))
    assert fit.noise_std_t == pytest.approx(sigma, rel=0.05)
    assert fit.frequency_std_hz == pytest.approx(fit.frequency_crb_hz, rel=0.05)
    assert 0.99 < fit.r_squared < 1.0
    assert "mHz" in fit.report() and "χ²/dof" in fit.report()


def test_theta_max_is_recovered_or_reported_as_not_determined():
    """Near 90° the start's θmax is often far off and a first step overshoots a bound; a
    rejected step must not freeze θmax where it was (it used to, at the spectral start). Where
    the data cannot separate θmax from κ the fit runs to a bound: then θmax is NaN and said to be
    not determined, never the bound passed off as a measurement."""
    rng = np.random.default_rng(5)
    for _ in range(60):
        theta0, amplitude = np.radians(rng.uniform(80, 100)), np.radians(rng.uniform(5, 25))
        y = signal_t(T, theta0, amplitude, FREQUENCY_HZ, PHASE_RAD, DAMPING_PER_S, KAPPA_T, offset_t=OFFSET_T)
        fit = fit_ringdown(y + 2e-10 * rng.standard_normal(N_SAMPLES), SAMPLE_RATE_HZ, theta0, 112.0)
        assert fit.ok, fit.message
        if "θmax not determined" in fit.message:
            assert math.isnan(fit.amplitude_rad) and math.isnan(fit.amplitude_std_rad)
            assert abs(pull(fit, "frequency_hz", FREQUENCY_HZ)) < 5
        else:
            assert abs(fit.amplitude_rad - amplitude) < FitOptions().amplitude_tolerance_rad


def test_general_sensor_direction():
    # Eq. S11 with a ≠ 0: the sensor also sees the 2a·cos θ component.
    rng = np.random.default_rng(12)
    direction = (0.6, 0.8)
    fit = fit_ringdown(
        clean(math.radians(50), *direction) + 5e-10 * rng.standard_normal(N_SAMPLES),
        SAMPLE_RATE_HZ,
        math.radians(50),
        112.0,
        options=FitOptions(sensor_direction=direction),
    )
    assert fit.ok and abs(pull(fit, "frequency_hz", FREQUENCY_HZ)) < 4
    assert fit.chi2_dof < 1 + 5 * math.sqrt(2 / N_SAMPLES)
    assert abs(pull(fit, "kappa_t", KAPPA_T)) < 4


def test_free_theta0_is_recovered():
    rng = np.random.default_rng(13)
    theta0 = math.radians(35.0)
    fit = fit_ringdown(
        clean(theta0) + 3e-10 * rng.standard_normal(N_SAMPLES),
        SAMPLE_RATE_HZ,
        theta0 + math.radians(4.0),
        112.0,
        options=FitOptions(theta0_free=True),
    )
    assert fit.ok and fit.theta0_free
    assert abs(pull(fit, "theta0_rad", theta0)) < 4


def test_difference_channel_cancels_common_mode_noise():
    # Two parallel sensors at different distances see the same 1/f laboratory noise; their
    # difference (Eq. S10) removes it. One channel alone is dominated by it.
    rng = np.random.default_rng(14)
    theta0 = math.radians(20.0)
    common = NoiseStream(NoiseModel(common_pink_t_per_rthz_at_1hz=3e-9), SAMPLE_RATE_HZ, rng).draw(0, N_SAMPLES)[:, 0]
    near = clean(theta0, kappa=2 * KAPPA_T) + common + 3e-10 * rng.standard_normal(N_SAMPLES)
    far = clean(theta0, kappa=KAPPA_T) + common + 3e-10 * rng.standard_normal(N_SAMPLES)
    pair = np.stack([near, far], axis=1)
    difference = fit_ringdown(pair, SAMPLE_RATE_HZ, theta0, 112.0)
    single = fit_ringdown(pair, SAMPLE_RATE_HZ, theta0, 112.0, options=FitOptions(channels="channel1"))
    assert difference.ok and abs(pull(difference, "frequency_hz", FREQUENCY_HZ)) < 4
    assert difference.chi2_dof < 1.2
    assert difference.kappa_t == pytest.approx(KAPPA_T, rel=0.05)
    assert not single.ok or single.chi2_dof > 3 * difference.chi2_dof


def test_joint_fit_of_both_channels():
    rng = np.random.default_rng(15)
    theta0 = math.radians(25.0)
    pair = np.stack(
        [
            clean(theta0, kappa=2 * KAPPA_T) + 4e-10 * rng.standard_normal(N_SAMPLES),
            clean(theta0) + 2e-10 * rng.standard_normal(N_SAMPLES),
        ],
        axis=1,
    )
    fit = fit_ringdown(pair, SAMPLE_RATE_HZ, theta0, 112.0, options=FitOptions(channels="both"))
    assert fit.ok and abs(pull(fit, "frequency_hz", FREQUENCY_HZ)) < 4
    assert {"kappa_t_1", "kappa_t_2", "offset_t_1", "offset_t_2"} <= set(fit.parameter_names)
    k2 = fit.covariance.shape[0] - 2
    assert fit.covariance[k2, k2] > 0


def test_axis_estimate_inverts_eq6_and_propagates_both_uncertainties():
    probe, f00, f00_std = PAPER_PROBE, 112.48, 2e-4
    field = 37e-6
    f = f00 + frequency_shift_hz(f00, probe.spring_nm_per_rad, probe.moment_am2 * field)
    rng = np.random.default_rng(16)
    fit = fit_ringdown(
        signal_t(T, 0.0, AMPLITUDE_RAD, f, PHASE_RAD, DAMPING_PER_S, KAPPA_T) + 3e-10 * rng.standard_normal(N_SAMPLES),
        SAMPLE_RATE_HZ,
        0.0,
        112.0,
    )
    estimate = estimate_along_axis(fit, probe, f00, f00_std)
    assert estimate.ok
    assert abs(estimate.field_along_axis_t - field) < 4 * estimate.field_along_axis_std_t
    # σ_B from Monte Carlo over both f and f00.
    f_draws = fit.frequency_hz + fit.frequency_std_hz * rng.standard_normal(100_000)
    f00_draws = f00 + f00_std * rng.standard_normal(100_000)
    b_draws = probe.spring_nm_per_rad / probe.moment_am2 * ((f_draws / f00_draws) ** 2 - 1)
    assert estimate.field_along_axis_std_t == pytest.approx(b_draws.std(), rel=0.02)
    # The gradient reading explains the same shift with l·m·G instead of m·B.
    assert estimate.gradient_equivalent_t_per_m * probe.lever_m == pytest.approx(estimate.field_along_axis_t, rel=1e-12)
