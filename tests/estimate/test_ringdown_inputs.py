"""Bad input never raises, never yields a number, and always says what went wrong."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mows.bench.estimator import SAMPLE_RATE_HZ, RingdownCase
from mows.estimate.axis import estimate_along_axis
from mows.estimate.ringdown import FitStatus, RingdownFit, fit_ringdown
from mows.physics.probe import PAPER_PROBE
from mows.physics.signal import kappa_t

THETA0 = math.radians(30.0)


@pytest.fixture(scope="module")
def good():
    return RingdownCase(THETA0, 40.0).draw(np.random.default_rng(0))


def assert_refused(result, status, *words):
    assert result.status == status, (result.status, result.message)
    assert result.message and all(w in result.message for w in words), result.message
    numeric = {
        k: v
        for k, v in dataclasses.asdict(result).items()
        if isinstance(v, float) and k not in ("theta0_rad", "duration_s", "start_offset_s")
    }
    assert all(math.isnan(v) for v in numeric.values()), numeric
    assert not estimate_along_axis(result, PAPER_PROBE, 112.48).ok


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_samples(good, bad):
    samples = good.copy()
    samples[[10, 500, 9000]] = bad
    assert_refused(fit_ringdown(samples, SAMPLE_RATE_HZ, THETA0, 112.0), FitStatus.INVALID_SAMPLES, "3")


def test_all_saturated(good):
    saturated = np.ones(good.shape, bool)
    assert_refused(
        fit_ringdown(np.clip(good, -1e-8, 1e-8), SAMPLE_RATE_HZ, THETA0, 112.0, saturated=saturated),
        FitStatus.SATURATED,
        "saturated",
    )


def test_saturated_coil_tail_is_cut_and_the_rest_fitted(good):
    saturated = np.zeros(good.shape, bool)
    saturated[:400] = True  # the first 20 ms, as when the coils switch off
    fit = fit_ringdown(good, SAMPLE_RATE_HZ, THETA0, 112.0, saturated=saturated)
    assert fit.ok, fit.message
    assert fit.start_offset_s == pytest.approx(400 / SAMPLE_RATE_HZ)
    assert fit.n_samples == good.size - 400


def test_too_short(good):
    assert_refused(fit_ringdown(good[:600], SAMPLE_RATE_HZ, THETA0, 112.0), FitStatus.TOO_SHORT, "periods")


def test_no_oscillation_in_pure_noise():
    noise = 1e-9 * np.random.default_rng(1).standard_normal(10_000)
    assert_refused(fit_ringdown(noise, SAMPLE_RATE_HZ, THETA0, 112.0), FitStatus.NO_OSCILLATION, "noise floor")


@pytest.mark.parametrize("rate", [0.0, -20_000.0, math.nan, math.inf, "20k", 1_000.0])
def test_wrong_sample_rate(good, rate):
    assert_refused(fit_ringdown(good, rate, THETA0, 112.0), FitStatus.BAD_SAMPLE_RATE, "Hz")


def test_missing_expected_frequency(good):
    assert_refused(fit_ringdown(good, SAMPLE_RATE_HZ, THETA0, math.nan), FitStatus.BAD_SAMPLE_RATE, "expected")


def test_beyond_spring_cancellation_gives_no_number():
    # Integrate the true equation of motion, J·θ'' = −kM·θ − m·B·sin θ − 2Jδ·θ', for B below
    # −kM/m: θ = 0 is unstable and the magnet runs to the housing stop (a stiff wall at 24°).
    probe = PAPER_PROBE
    field = 1.3 * probe.cancellation_field_t
    stop = probe.theta_stop_rad

    def rhs(_, state):
        theta, rate = state
        wall = -1e3 * probe.spring_nm_per_rad * (abs(theta) - stop) * np.sign(theta) if abs(theta) > stop else 0.0
        torque = -probe.spring_nm_per_rad * theta - probe.moment_am2 * field * math.sin(theta) + wall
        return [rate, torque / probe.inertia_kgm2 - 2 * probe.damping_per_s * rate]

    t = np.arange(10_000) / SAMPLE_RATE_HZ
    theta = solve_ivp(rhs, (0, t[-1]), [0.05, 0.0], t_eval=t, rtol=1e-9, atol=1e-12, max_step=1e-4).y[0]
    kappa = kappa_t(probe.moment_am2, 0.0675)
    samples = -kappa * np.sin(theta) + 1e-10 * np.random.default_rng(2).standard_normal(t.size)
    fit = fit_ringdown(samples, SAMPLE_RATE_HZ, 0.0, probe.f00_hz)
    assert fit.status in (FitStatus.NO_OSCILLATION, FitStatus.NEGATIVE_STIFFNESS, FitStatus.BAD_FIT), fit.report()
    assert_refused(fit, fit.status, "")


def test_a_good_ringdown_passes_the_same_checks(good):
    # The refusals above are specific: the unmodified data fit, with every number finite.
    fit = fit_ringdown(good, SAMPLE_RATE_HZ, THETA0, 112.0)
    assert fit.ok and all("not determined" in part for part in filter(None, fit.message.split("; ")))
    assert all(
        math.isfinite(v)
        for v in (fit.frequency_hz, fit.frequency_std_hz, fit.frequency_crb_hz, fit.chi2_dof, fit.r_squared, fit.snr_db)
    )


def test_a_report_says_a_spread_is_not_determined_instead_of_printing_nan():
    fit = RingdownFit(
        status=FitStatus.OK,
        frequency_hz=110.0,
        frequency_std_hz=1e-4,
        frequency_crb_hz=1e-4,
        damping_per_s=1.8,
        amplitude_rad=math.radians(0.65),
        theta0_rad=0.0,
        chi2_dof=1.0,
        r_squared=0.99,
        snr_db=40.0,
    )
    assert math.isnan(fit.amplitude_std_rad)  # no covariance: the data did not determine it
    assert "θmax = 0.65° (its σ not determined)" in fit.report() and "nan" not in fit.report()
