"""Fluxgates: exact dipole pick-up against Eqs. S8–S10, digitisation, noise spectra."""

import numpy as np
import pytest
import scipy.constants
from scipy import signal

from mows.physics.fluxgate import (
    PAPER_SPACING_M,
    Fluxgate,
    FluxgatePair,
    NoiseModel,
    digitise,
    dipole_pickup_t,
)
from mows.sim.noise import NoiseStream

M = 0.89e-3  # A·m², the paper's magnet
R = 0.06  # m, probe to near sensor


def kappa(r_m):
    return scipy.constants.mu_0 * M / (4 * np.pi * r_m**3)


def moments(theta):
    return M * np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], axis=-1)


THETA = np.linspace(-np.pi, np.pi, 2001)


@pytest.mark.parametrize("axis", [(0, 1, 0), (1, 0, 0), (0.6, -0.8, 0), (0.3, 0.4, np.sqrt(0.75))])
def test_pickup_on_the_sensor_line_is_eq_s9(axis):
    # Moment m(cos θ, sin θ, 0) at the origin, sensor at (r, 0, 0) along (a, b, c):
    # S = κ(2a·cos θ − b·sin θ), κ = μ0m/(4πr³)   (Eqs. S8, S9).
    a, b, _ = axis
    sensor = Fluxgate([R, 0, 0], axis)
    pickup = dipole_pickup_t(sensor, np.zeros((len(THETA), 3)), moments(THETA))
    np.testing.assert_allclose(
        pickup, kappa(R) * (2 * a * np.cos(THETA) - b * np.sin(THETA)), rtol=0, atol=1e-13 * kappa(R)
    )


def test_moving_magnet_on_the_line_sees_its_own_distance():
    # A magnet displaced to (x, 0, 0) reads as a dipole at r − x: the exact pick-up has no
    # fixed-distance approximation in it.
    x = np.linspace(-2e-3, 2e-3, len(THETA))
    sensor = Fluxgate([R, 0, 0], [0, 1, 0])
    pickup = dipole_pickup_t(sensor, np.stack([x, 0 * x, 0 * x], axis=-1), moments(THETA))
    np.testing.assert_allclose(pickup, -kappa(R - x) * np.sin(THETA), rtol=0, atol=1e-13 * kappa(R))


def test_differential_pair_gives_eq_s10_effective_distance():
    pair = FluxgatePair.paper()
    r_eff = (R**-3 - (R + PAPER_SPACING_M) ** -3) ** (-1 / 3)
    assert r_eff == pytest.approx(0.0675, rel=1e-14)  # the paper's r_eff at r = 6 cm
    assert PAPER_SPACING_M == pytest.approx(0.030, abs=2e-4)
    pickup = pair.pickup_t(np.zeros(3), moments(THETA))
    assert pickup.shape == (len(THETA), 2)
    np.testing.assert_allclose(
        pickup[:, 0] - pickup[:, 1],
        -kappa(r_eff) * np.sin(THETA),  # Eq. S12, b = 1
        rtol=0,
        atol=1e-12 * kappa(r_eff),
    )


def test_saturation_is_flagged_and_clipped():
    sensor = Fluxgate([R, 0, 0], [0, 1, 0])
    values = np.array([-25e-6, -10e-6, -3e-6, 0.0, 9.99999e-6, 10.0001e-6, 1e-3])
    readings, saturated = digitise(values, sensor)
    assert saturated.tolist() == [True, False, False, False, False, True, True]
    assert np.all(np.abs(readings) <= 10e-6)
    assert readings[0] == -10e-6 and readings[-1] == 10e-6


def test_quantisation_rounds_to_the_nearest_step():
    sensor = Fluxgate([R, 0, 0], [0, 1, 0])
    values = np.random.default_rng(4).uniform(-9e-6, 9e-6, 10_000)
    readings, saturated = digitise(values, sensor)
    steps = readings / 1e-10
    assert not saturated.any()
    assert np.allclose(steps, np.round(steps), rtol=0, atol=1e-6)
    assert np.max(np.abs(readings - values)) <= 0.5e-10 * (1 + 1e-6)
    assert np.max(np.abs(readings - values)) > 0.49e-10  # it does round, to the resolution
    assert len(np.unique(np.round(steps))) > 9000


def test_offset_nulling_keeps_the_signal_in_range_in_the_earth_field():
    # 50 µT of Earth's field would saturate a ±10 µT sensor; nulled, only the ring-down remains.
    earth = np.array([20e-6, 45e-6, -10e-6])
    pair = FluxgatePair.paper()
    pickup = pair.pickup_t(np.zeros(3), moments(THETA))
    raw = pickup + pair.component_t(np.broadcast_to(earth, (2, 3)))
    assert pair.digitise(raw)[1].all()
    nulled = pair.with_offsets_nulled(np.broadcast_to(earth, (2, 3)))
    readings, saturated = nulled.digitise(raw)
    assert not saturated.any()
    assert np.max(np.abs(readings - pickup)) <= 0.5e-10 * (1 + 1e-6)


FS = 1000.0


def psd(x, nperseg=2**14):
    return signal.welch(x, fs=FS, nperseg=nperseg, axis=0)


def test_pink_noise_slope_and_level():
    # One-sided ASD = A·f^(−1/2): PSD·f = A² and log PSD has slope −1.
    asd = 3e-11
    pink = NoiseStream(NoiseModel(common_pink_t_per_rthz_at_1hz=asd), FS, np.random.default_rng(5)).draw(0, 2**20)
    f, p = psd(pink[:, 0])
    band = (f >= 0.5) & (f <= 50)
    slope = np.polyfit(np.log(f[band]), np.log(p[band]), 1)[0]
    assert slope == pytest.approx(-1.0, abs=0.03)
    assert np.sqrt(np.mean(p[band] * f[band])) == pytest.approx(asd, rel=0.03)


def test_white_levels_and_common_mode_cancellation():
    model = NoiseModel(
        common_white_t_per_rthz=2e-11, common_pink_t_per_rthz_at_1hz=5e-11, sensor_white_t_per_rthz=1e-12, mains_t=1e-9
    )
    noise = NoiseStream(model, FS, np.random.default_rng(6)).draw(0, 2**18)
    assert noise.shape == (2**18, 2)
    # The difference keeps only the two independent white parts: PSD 2·σ², flat.
    f, p = psd(noise[:, 0] - noise[:, 1], 2**12)
    band = (f > 1) & (f < 450)
    assert np.sqrt(np.mean(p[band]) / 2) == pytest.approx(1e-12, rel=0.03)
    # Each channel is dominated by the common part: white level at high f, mains at 50 Hz.
    f, p = psd(noise[:, 0], 2**12)
    high = (f > 300) & (f < 450)
    assert np.sqrt(np.mean(p[high])) == pytest.approx(np.hypot(2e-11, 1e-12), rel=0.05)
    line = np.argmin(np.abs(f - 50))
    assert p[line] > 100 * np.median(p[(f > 40) & (f < 60)])
    # Without sensor noise the common part cancels exactly.
    common_only = NoiseModel(common_white_t_per_rthz=2e-11, common_pink_t_per_rthz_at_1hz=5e-11, mains_t=1e-9)
    noise = NoiseStream(common_only, FS, np.random.default_rng(7)).draw(0, 4096)
    assert np.all(noise[:, 0] == noise[:, 1]) and np.std(noise[:, 0]) > 1e-10


def test_noise_parameters_are_checked():
    with pytest.raises(ValueError, match="sensor_white_t_per_rthz"):
        NoiseModel(sensor_white_t_per_rthz=-1.0)
    with pytest.raises(ValueError, match="resolution_t"):
        Fluxgate([0, 0, 0], [0, 1, 0], resolution_t=0.0)
