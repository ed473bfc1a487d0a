"""A swing measured through the pickup about the undeflected lever, turned into the swing about
the rest angle (mows.physics.ringdown_average.swing_about_rest_rad).

Requirement: the swing about θs has the signal's variance of the measured one; for a small swing
the signal is linear in it, so the two differ by the pickup's slopes, g'(0)/g'(θs).
"""

import math

import numpy as np

from mows.physics.ringdown_average import pickup_variance, swing_about_rest_rad

SINE = (0.0, -1j)  # g(x) = Re(−i·e^(ix)) = sin x: slope cos θ


def test_a_small_swing_scales_by_the_ratio_of_the_pickups_slopes():
    rest = np.array([-0.3, -0.05, 0.0, 0.05, 0.3])
    swing = swing_about_rest_rad(1e-4, SINE, 2.0, 0.5, rest)
    np.testing.assert_allclose(swing, 1e-4 / np.cos(rest), rtol=1e-5)


def test_the_converted_swing_has_the_measured_signals_variance():
    pickup = (0.1, -0.8j, 0.3 + 0.2j, 0.05j)  # strong second harmonic, as off the sensors' axis
    swing = float(swing_about_rest_rad(0.15, pickup, 1.8, 0.5, 0.015))
    assert abs(swing / 0.15 - 1.0) > 0.01  # the rest angle matters at this size
    measured = pickup_variance(0.15, pickup, 1.8, 0.5, 0.0)
    assert math.isclose(float(pickup_variance(swing, pickup, 1.8, 0.5, 0.015)), float(measured), rel_tol=1e-9)


def test_no_signal_gives_no_swing():
    assert np.isnan(swing_about_rest_rad(0.1, (1.0,), 2.0, 0.5, 0.01))  # a constant pickup
