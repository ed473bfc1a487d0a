"""The calibrated f00's uncertainty in the map: one error shared by every ring-down.

A calibrated f00 off by δ shifts every measured Δf = f − f00 by −δ at once. The decomposition
must carry that as one common error (mostly into Gs, the constant term), not as independent
noise on each ring-down, which averages it away. The check is independent of the covariance
algebra: refit with f00 moved by ±δ and the shifts moved with it.
"""

import math

import numpy as np
import pytest

from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.decompose import decompose
from mows.sweep.record import SweepPoint, SweepRecord
from mows.sweep.shift_model import model_shift_hz

ANGLES = np.radians(np.arange(0.0, 360.0, 15.0))
TRUE = np.array([60e-6, -25e-6, 4e-3, 1.5e-3, -2e-3, 0.0])  # Bx, By, Gs, Gd, Gxy, Δf00
STD_HZ, F00_STD_HZ, DELTA_HZ = 3e-4, 2e-3, 1e-3


def shifts(seed=1):
    rng = np.random.default_rng(seed)
    return model_shift_hz(TRUE, ANGLES, P, P.f00_hz, "published") + STD_HZ * rng.standard_normal(ANGLES.size)


def gradient_variance(decomposition) -> np.ndarray:
    return np.diag(decomposition.gradient_covariance)


def test_the_f00_uncertainty_enters_the_gradient_as_one_shared_error():
    shift, std = shifts(), np.full(ANGLES.size, STD_HZ)
    alone = decompose(ANGLES, shift, std, P, P.f00_hz, model="published")
    with_f00 = decompose(ANGLES, shift, std, P, P.f00_hz, model="published", f00_std_hz=F00_STD_HZ)
    up = decompose(ANGLES, shift - DELTA_HZ, std, P, P.f00_hz + DELTA_HZ, model="published")
    down = decompose(ANGLES, shift + DELTA_HZ, std, P, P.f00_hz - DELTA_HZ, model="published")
    slope = (up.gradient_t_per_m - down.gradient_t_per_m) / (2.0 * DELTA_HZ)  # T/m per Hz of f00
    expected = gradient_variance(alone) + (slope * F00_STD_HZ) ** 2
    assert gradient_variance(with_f00) == pytest.approx(expected, rel=1e-3)
    assert abs(slope[0]) > 0 and (slope[0] * F00_STD_HZ) ** 2 > 10 * gradient_variance(alone)[0]
    # the field is the 1θ0 harmonic: a constant offset hardly moves it (through the factor f00)
    field_variance = np.diag(with_f00.field_covariance_t2)
    assert np.allclose(field_variance, np.diag(alone.field_covariance_t2), rtol=0.02, atol=0.0)
    # Folded into every ring-down's σ instead (as before), the shared error is averaged away:
    # Gxx's σ comes out too small, and the field's too large.
    folded = decompose(ANGLES, shift, np.hypot(std, F00_STD_HZ), P, P.f00_hz, model="published")
    assert math.sqrt(gradient_variance(folded)[0]) < 0.5 * math.sqrt(gradient_variance(with_f00)[0])
    assert folded.field_covariance_t2[0, 0] > 10 * field_variance[0]


def test_a_sweep_record_takes_the_f00_uncertainty_out_of_the_shifts_sigma():
    # The estimator reports σ_shift = √(σ_f² + σ_f00²): the record splits it back.
    shift = shifts(2)
    points = [
        SweepPoint(t, P.f00_hz + s, STD_HZ, s, math.hypot(STD_HZ, F00_STD_HZ), 0.4, 1.8, 0.5, 0.0)
        for t, s in zip(ANGLES, shift)
    ]
    record = SweepRecord(points)
    assert record.f00_std_hz() == pytest.approx(F00_STD_HZ, rel=1e-9)
    direct = decompose(ANGLES, shift, np.full(ANGLES.size, STD_HZ), P, P.f00_hz, "published", f00_std_hz=F00_STD_HZ)
    mapped = record.decompose(P, P.f00_hz, model="published")
    assert np.allclose(mapped.gradient_covariance, direct.gradient_covariance, rtol=1e-6, atol=0.0)
    # f00 fitted instead: its calibration's σ has nothing to add
    free = record.decompose(P, P.f00_hz, model="published", f00_free=True)
    assert np.isnan(free.gradient_covariance[0, 0]) and np.isfinite(free.gradient_covariance[1, 1])
