"""The housing stop's uncertainty in the map: one error shared by every ring-down of a sweep.

In a strong field the fits do not determine θmax, so every ring-down's start swing is the stop
less its rest angle, from the probe file's stop. An error δ in that stop moves every ring-down's
swing at once, and through the field spring's amplitude dependence (docs/physics.md §6.3, §6.4)
Bx by about 26 nT per 0.01° at 3.4 mT. The decomposition must carry it as one common error,
not as independent noise per ring-down. The checks are independent of the covariance algebra:
refits with the stop moved by ±δ, and sweeps whose stop is drawn from its distribution.
"""

import math

import numpy as np
import pytest
from scipy.stats import norm

from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.decompose import decompose
from mows.sweep.planner import AdaptivePlanner, PlanEnd, PrecisionGoal, achieved_std
from mows.sweep.record import SweepPoint, SweepRecord
from mows.sweep.shift_model import Ringdowns, model_shift_hz

ANGLES = np.radians(np.arange(0.0, 360.0, 15.0))
TRUE = np.array([3.4e-3, 12e-6, 2e-3, -1e-3, 0.5e-3, 0.0])  # Bx, By, Gs, Gd, Gxy, Δf00
STD_HZ = 6e-4  # a ring-down's σ in 3.4 mT, as the recorded sweeps fit it (Bx's σ ~45 nT)
STOP_STD_RAD = math.radians(0.04)
DELTA_RAD = math.radians(0.02)


def ringdowns(stop_rad: float, stop_std_rad: float = 0.0) -> Ringdowns:
    n = ANGLES.size
    return Ringdowns(
        stop_rad, np.full(n, P.damping_per_s), np.full(n, 0.5), None, start_offset_s=0.003, stop_std_rad=stop_std_rad
    )


def shifts(stop_rad: float, rng) -> np.ndarray:
    exact = model_shift_hz(TRUE, ANGLES, P, P.f00_hz, "first_principles", ringdowns(stop_rad))
    return exact + STD_HZ * rng.standard_normal(ANGLES.size)


def fit(shift, stop_rad: float, stop_std_rad: float = 0.0):
    return decompose(
        ANGLES, shift, np.full(ANGLES.size, STD_HZ), P, P.f00_hz, ringdowns=ringdowns(stop_rad, stop_std_rad)
    )


def variances(d) -> np.ndarray:
    return np.r_[np.diag(d.field_covariance_t2), np.diag(d.gradient_covariance)]


def values(d) -> np.ndarray:
    return np.r_[d.field_t, d.gradient_t_per_m]


def test_the_stop_uncertainty_enters_field_and_gradient_as_one_shared_error():
    stop = P.theta_stop_rad
    shift = shifts(stop, np.random.default_rng(3))
    alone, carried = fit(shift, stop), fit(shift, stop, STOP_STD_RAD)
    up, down = fit(shift, stop + DELTA_RAD), fit(shift, stop - DELTA_RAD)
    slope = (values(up) - values(down)) / (2.0 * DELTA_RAD)  # per radian of stop
    expected = variances(alone) + (slope * STOP_STD_RAD) ** 2
    assert variances(carried) == pytest.approx(expected, rel=0.02)
    # at 3.4 mT the stop's share is most of Bx's σ: ~26 nT per 0.01°
    assert abs(slope[0]) * math.radians(0.01) == pytest.approx(26e-9, rel=0.3)
    assert variances(carried)[0] > 3.0 * variances(alone)[0]


@pytest.mark.slow
def test_sweeps_whose_stop_differs_from_the_files_have_unit_pulls():
    """40 sweeps, each released at a stop drawn from N(24°, 0.04°) and decomposed with the
    file's 24° ± 0.04°: Bx's pulls have sd 1 (within the sd's Monte Carlo error 0.11, 3σ). Without
    the stop in the covariance their sd is ~2.3."""
    rng = np.random.default_rng(20261207)
    pulls, bare = [], []
    for _ in range(40):
        shift = shifts(P.theta_stop_rad + STOP_STD_RAD * rng.standard_normal(), rng)
        carried, alone = fit(shift, P.theta_stop_rad, STOP_STD_RAD), fit(shift, P.theta_stop_rad)
        pulls.append((carried.field_t[0] - TRUE[0]) / math.sqrt(carried.field_covariance_t2[0, 0]))
        bare.append((alone.field_t[0] - TRUE[0]) / math.sqrt(alone.field_covariance_t2[0, 0]))
    assert abs(np.std(pulls, ddof=1) - 1.0) < 3 * 0.11, pulls
    assert abs(np.mean(pulls)) < 3 / math.sqrt(40), pulls
    assert np.std(bare, ddof=1) > 1.6, bare


def points(amplitude_rad, rest_offset_rad=math.nan):
    shift = shifts(P.theta_stop_rad, np.random.default_rng(5))
    return [
        SweepPoint(
            t,
            P.f00_hz + s,
            STD_HZ,
            s,
            STD_HZ,
            a,
            P.damping_per_s,
            0.5,
            0.0,
            rest_offset_rad=rest_offset_rad,
            rest_offset_std_rad=1e-4,
            start_offset_s=0.003,
        )
        for t, s, a in zip(ANGLES, shift, amplitude_rad)
    ]


def test_a_sweep_without_the_stop_from_its_fits_carries_the_probe_files_sigma():
    undetermined = SweepRecord(points(np.full(ANGLES.size, np.nan)))
    assert undetermined.stop_std_rad(fallback_std_rad=STOP_STD_RAD) == STOP_STD_RAD
    probe = P.replace(theta_stop_std_rad=STOP_STD_RAD)
    mapped = undetermined.decompose(probe, P.f00_hz, curvature=False)
    exact_stop = undetermined.decompose(P.replace(theta_stop_std_rad=1e-9), P.f00_hz, curvature=False)
    assert mapped.field_covariance_t2[0, 0] > 3.0 * exact_stop.field_covariance_t2[0, 0]


def test_a_stop_pooled_from_its_fits_carries_the_medians_standard_error():
    # Fits that determined θmax: stops at the normal quantiles of sd 0.05° about 24°, rest offset 0.
    scatter = math.radians(0.05) * norm.ppf((np.arange(ANGLES.size) + 0.5) / ANGLES.size)
    swing = (P.theta_stop_rad + scatter) * math.exp(-P.damping_per_s * 0.003)
    record = SweepRecord(points(swing, 0.0))
    # the median's standard error of a normal sample: √(π/2)·sd/√n
    assert record.stop_std_rad(np.zeros(ANGLES.size), 1.0) == pytest.approx(
        math.sqrt(math.pi / 2) * math.radians(0.05) / math.sqrt(ANGLES.size), rel=0.05
    )


def test_an_adaptive_sweep_whose_target_lies_below_the_stops_share_ends_saying_so():
    """A target no number of ring-downs reaches (the stop's share of Bx's σ at 3.4 mT is 2.6 µT
    for a stop known to 1°) ends the sweep at once, saying why, instead of running on forever."""
    stop = P.theta_stop_rad
    decomposition = fit(shifts(stop, np.random.default_rng(4)), stop, math.radians(1.0))
    shared = decomposition.shared_std
    assert shared[0] == pytest.approx(2.6e-6, rel=0.3) and np.all(shared <= achieved_std(decomposition))
    planner = AdaptivePlanner(P, P.f00_hz, PrecisionGoal("B", 20e-9), repeat_s=1.0, turn_s=0.5)
    end = planner.next(SweepRecord(points(np.full(ANGLES.size, np.nan))), decomposition, 10.0)
    assert isinstance(end, PlanEnd) and not end.reached and "shared by every ring-down" in end.message
    # a target above the stop's share (Gxy: 1.4 µT/m), not yet reached (9 µT/m), plans on
    loose = AdaptivePlanner(P, P.f00_hz, PrecisionGoal("gxy", gradient_std_t_per_m=5e-6), repeat_s=1.0, turn_s=0.5)
    assert not isinstance(loose.next(SweepRecord(points(np.full(ANGLES.size, np.nan))), decomposition, 10.0), PlanEnd)
