"""Signal model (Eqs. S2, S8-S12) against the paper's geometry and exact trigonometry."""

import math

import numpy as np
import pytest

from mows.physics.signal import effective_distance_m, kappa_t, peak_amplitude, ringdown_angle_rad, signal_t


def test_effective_distance_of_the_paper_setup():
    # Supplement: r = 6 cm and r_eff = 6.75 cm imply a sensor spacing of about 3 cm.
    assert effective_distance_m(0.06, 0.030) == pytest.approx(0.0675, abs=2e-4)


def test_kappa_is_the_on_axis_dipole_field():
    assert kappa_t(0.89e-3, 0.0675) == pytest.approx(1e-7 * 0.89e-3 / 0.0675**3, rel=1e-8)


def test_zero_to_ninety_degree_amplitude_ratio_is_15_2():
    # docs/physics.md §3 corrects Eq. 3: ratio = sin θmax / ((1 − cos θmax)/2) = 15.19 at 15°.
    theta_max = math.radians(15.0)
    t = np.linspace(0, 1 / 100, 20001)  # one undamped period
    swing = [np.ptp(signal_t(t, th0, theta_max, 100.0, 0.0, 0.0, 1.0)) / 2 for th0 in (0.0, math.pi / 2)]
    assert swing[0] / swing[1] == pytest.approx(15.19, abs=0.01)
    assert peak_amplitude(0.0, theta_max) / peak_amplitude(math.pi / 2, theta_max) == pytest.approx(
        swing[0] / swing[1], rel=1e-6
    )
    assert swing[1] == pytest.approx(theta_max**2 / 4, rel=0.01)


def test_ringdown_decays_at_delta():
    t = np.array([0.0, 1.0])
    assert ringdown_angle_rad(t, 0.4, 100.0, 0.0, 1.8)[1] == pytest.approx(0.4 * math.exp(-1.8))


def test_general_sensor_direction_reduces_to_eq_s12():
    t = np.linspace(0, 0.1, 500)
    args = (t, 0.3, 0.4, 112.0, 0.2, 1.8, 2e-7)
    np.testing.assert_allclose(
        signal_t(*args, a=0.0, b=1.0, offset_t=1e-6),
        -2e-7 * np.sin(0.3 + ringdown_angle_rad(t, 0.4, 112.0, 0.2, 1.8)) + 1e-6,
    )
