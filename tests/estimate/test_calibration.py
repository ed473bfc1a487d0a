"""f00 calibration from ring-downs in a known field (Eq. 6 solved for f00), without ROS."""

import math

import numpy as np
import pytest

from mows.estimate.calibration.f00 import CalibrationStatus, F00Calibration
from mows.physics.probe import PAPER_PROBE as P
from mows.records.results import Result


def field_for_ratio(ratio: float) -> float:
    """The field along the axis that multiplies the spring by ``ratio``: kM + m·B = ratio·kM."""
    return (ratio - 1.0) * P.spring_nm_per_rad / P.moment_am2


def offer_all(calibration, frequencies_hz, std_hz):
    outcomes = [calibration.offer(f, std_hz) for f in frequencies_hz]
    assert all(o is None for o in outcomes[:-1])
    return outcomes[-1]


def test_a_field_that_quadruples_the_spring_doubles_the_frequency():
    # Eq. 6: f = f00·√(k/kM); k = 4·kM gives f = 2·f00, whatever f00 is.
    outcome = offer_all(F00Calibration(P, field_for_ratio(4.0), 3, 1.0), [200.0, 200.2, 199.8], 0.1)
    assert outcome.ok and outcome.status is CalibrationStatus.OK and outcome.n_used == 3
    assert isinstance(outcome, Result) and "from 3 ring-downs" in outcome.report()
    assert outcome.f00_hz == pytest.approx(100.0, rel=1e-12)
    # σ: the larger of the scatter of the mean (f00 each 100 ± 0.1 Hz: 0.1/√3) and the fits'
    # own σ carried through Eq. 6 (0.1/2 Hz each: 0.05/√3).
    assert outcome.f00_std_hz == pytest.approx(0.1 / math.sqrt(3), rel=1e-9)


def test_in_zero_field_f00_is_the_mean_frequency_and_one_ringdown_keeps_its_own_sigma():
    outcome = offer_all(F00Calibration(P, 0.0, 1, 1.0), [101.5], 2e-3)
    assert outcome.ok and outcome.f00_hz == 101.5 and outcome.f00_std_hz == pytest.approx(2e-3)


def test_calibrated_f00_of_the_probe_in_a_field_matches_its_constants_within_sigma():
    """Ring-downs at the probe's exact frequency in 1 mT (damping included), with noise: the
    calibration returns the probe's f00 (damping shifts Eq. 6's inverse by < 1e-6 Hz here)."""
    field_t, std_hz, n = 1e-3, 5e-4, 5
    true_f_hz = float(P.frequency_for_spring_hz(P.spring_nm_per_rad + P.moment_am2 * field_t))
    assert true_f_hz > P.f00_hz + 1.0  # the field matters: inverting Eq. 6 is not a no-op
    rng = np.random.default_rng(7)
    estimates, sigmas = [], []
    for _ in range(400):
        outcome = offer_all(F00Calibration(P, field_t, n, 1.0), true_f_hz + std_hz * rng.standard_normal(n), std_hz)
        estimates.append(outcome.f00_hz)
        sigmas.append(outcome.f00_std_hz)
    estimates = np.array(estimates)
    propagated = std_hz / math.sqrt(1.0 + P.moment_am2 * field_t / P.spring_nm_per_rad) / math.sqrt(n)
    assert abs(estimates.mean() - P.f00_hz) < 4 * propagated / math.sqrt(len(estimates))
    # The spread of f00 is the fits' σ carried through Eq. 6 (400 trials: ±7 % at 2σ).
    assert estimates.std(ddof=1) / propagated == pytest.approx(1.0, abs=0.1)
    # The reported σ is never below the propagated one (max of the two estimates).
    assert min(sigmas) >= propagated * (1 - 1e-12)


def test_time_up_says_how_many_ringdowns_came_and_nothing_is_taken_after():
    calibration = F00Calibration(P, 0.0, 3, 2.5)
    assert calibration.offer(100.0, 1e-3) is None
    outcome = calibration.time_up()
    assert outcome.status is CalibrationStatus.TOO_FEW_RINGDOWNS and not outcome.ok and outcome.n_used == 1
    assert "only 1 of 3 OK ring-downs in 2.5 s" in outcome.message
    assert math.isnan(outcome.f00_hz)
    assert calibration.offer(100.0, 1e-3) is None and calibration.time_up() is None and calibration.done


@pytest.mark.parametrize(
    "field_t, n, timeout_s",
    [
        (0.0, 0, 1.0),  # no ring-down asked for
        (0.0, 3, 0.0),  # no time to collect them
        (0.0, 3, math.nan),
        (P.cancellation_field_t, 3, 1.0),  # spring cancellation: Eq. 6 has no real root
        (2 * P.cancellation_field_t, 3, 1.0),
    ],
)
def test_requests_that_cannot_be_met_are_refused_with_the_reason(field_t, n, timeout_s):
    with pytest.raises(ValueError, match="spring cancellation"):
        F00Calibration(P, field_t, n, timeout_s)
