"""Excitation setups: coil field perpendicular to the moment for every θ0, the current cap."""

import numpy as np
import pytest
import scipy.constants
from hypothesis import given, settings
from hypothesis import strategies as st

from mows.physics.coils import (
    LSIP330_LENGTH_M,
    LSIP330_LOOPS,
    LSIP330_RADIUS_M,
    LSIP330_TURNS,
    PASCO_RADIUS_M,
    PASCO_TURNS,
    CurrentCap,
    helmholtz,
    largest_spacing,
    pasco_pair,
    setup_from_dict,
)

SETUPS = {"largest_spacing": largest_spacing(), "helmholtz": helmholtz()}
THETA0 = np.radians(np.arange(0.0, 360.0, 15.0))


def moment_direction(theta0):
    return np.stack([np.cos(theta0), np.sin(theta0), np.zeros_like(theta0)], axis=-1)


def angle_to_moment_deg(field, theta0):
    cosine = np.einsum("...i,...i->...", field, moment_direction(theta0)) / np.linalg.norm(field, axis=-1)
    return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))


def on_axis_coil_field_per_ampere(distance_m):
    """Σ over the model's loops of μ0·n·R²/(2(R² + z²)^{3/2}), n = N/loops, at the loops' offsets."""
    slices = ((np.arange(LSIP330_LOOPS) + 0.5) / LSIP330_LOOPS - 0.5) * LSIP330_LENGTH_M
    z = distance_m + slices
    n = LSIP330_TURNS / LSIP330_LOOPS
    return np.sum(scipy.constants.mu_0 * n * LSIP330_RADIUS_M**2 / (2 * (LSIP330_RADIUS_M**2 + z**2) ** 1.5))


@pytest.mark.parametrize("name, directions_deg", [("largest_spacing", (45.0, 135.0)), ("helmholtz", (90.0, 180.0))])
def test_each_coil_field_at_the_probe_points_along_its_axis(name, directions_deg):
    # Coil 1 along +45° and coil 2 along +135° (largest spacing); +y and −x (Helmholtz setup).
    per_ampere = SETUPS[name].coil_field_per_ampere_t([0.0, 0.0, 0.0])
    magnitude = on_axis_coil_field_per_ampere(0.10)
    expected = magnitude * moment_direction(np.radians(np.array(directions_deg)))
    np.testing.assert_allclose(per_ampere, expected, rtol=0, atol=1e-12 * magnitude)


@pytest.mark.parametrize("name", SETUPS)
def test_coil_field_at_the_probe_is_perpendicular_to_the_moment_for_every_theta0(name):
    setup = SETUPS[name]
    currents = setup.currents_a(THETA0, 10.0)  # (24, 2)
    field = setup.field_t(np.zeros(3), currents)  # (24, 3)
    assert np.all(np.abs(angle_to_moment_deg(field, THETA0) - 90.0) < 1e-9)
    # A·b·(−sin θ0, cos θ0): constant magnitude, turning with the probe.
    b = 10.0 * on_axis_coil_field_per_ampere(0.10)
    expected = b * np.stack([-np.sin(THETA0), np.cos(THETA0), np.zeros_like(THETA0)], axis=-1)
    np.testing.assert_allclose(field, expected, rtol=0, atol=1e-12 * b)


@pytest.mark.parametrize("name", SETUPS)
def test_perpendicular_within_two_degrees_where_the_magnet_swings(name):
    # The magnet stays within l·sin(24°) ≈ 0.8 mm of its rest position; off a coil's axis the
    # field turns by ≈ (3/2)·δ/D rad (D = 10 cm), i.e. 1.7° at δ = 1 mm.
    setup = SETUPS[name]
    rng = np.random.default_rng(3)
    offsets = rng.normal(size=(30, 3))
    offsets *= 1e-3 / np.linalg.norm(offsets, axis=-1, keepdims=True)
    for theta0 in THETA0:
        field = setup.field_t(offsets, setup.currents_a(theta0, 10.0))
        assert np.all(np.abs(angle_to_moment_deg(field, np.full(len(offsets), theta0)) - 90.0) < 2.0)


@pytest.mark.parametrize("name", SETUPS)
def test_coils_stay_clear_of_the_sensor_line(name):
    # The fluxgates sit on the +x axis at 6 and 9 cm: every loop of every coil keeps at
    # least 3 cm (centre distance minus radius) from the segment probe–far sensor.
    for coil in SETUPS[name].coils:
        centres = np.array([loop.center_m for loop in coil.sources])
        along = np.clip(centres[:, 0], 0.0, 0.09)
        gap = np.linalg.norm(centres - np.stack([along, 0 * along, 0 * along], axis=-1), axis=-1) - LSIP330_RADIUS_M
        assert np.all(gap > 0.03)


def test_current_cap_refuses_and_never_clips():
    setup = SETUPS["largest_spacing"]
    assert np.max(np.abs(setup.currents_a(np.radians(45.0), 10.0))) == pytest.approx(10.0, rel=1e-15)
    with pytest.raises(ValueError, match="exceeds the cap of 10 A"):
        setup.currents_a(0.0, 10.001)
    with pytest.raises(ValueError, match="amplitude_a"):
        setup.currents_a(0.0, -1.0)
    with pytest.raises(ValueError, match="12.5 A exceeds the cap of 10 A"):
        CurrentCap(10.0).check([1.0, -12.5])
    with pytest.raises(ValueError, match="limit_a"):
        CurrentCap(0.0)


@settings(max_examples=200, deadline=None)
@given(
    name=st.sampled_from(sorted(SETUPS)),
    theta0=st.floats(-20.0, 20.0, allow_nan=False),
    amplitude=st.floats(0.0, 10.0, allow_nan=False),
)
def test_no_commanded_current_exceeds_the_cap(name, theta0, amplitude):
    assert np.all(np.abs(SETUPS[name].currents_a(theta0, amplitude)) <= 10.0)


@settings(max_examples=50, deadline=None)
@given(amplitude=st.floats(10.0, 1e6, exclude_min=True, allow_nan=False))
def test_every_amplitude_above_the_cap_is_refused(amplitude):
    with pytest.raises(ValueError, match="cap"):
        SETUPS["helmholtz"].currents_a(0.3, amplitude)


def test_yaml_round_trip_and_presets():
    points = np.array([[0.0, 0.0, 0.0], [0.01, -0.02, 0.003]])
    for setup in SETUPS.values():
        again = setup_from_dict(setup.to_dict())
        np.testing.assert_allclose(again.currents_a(THETA0, 7.0), setup.currents_a(THETA0, 7.0), rtol=0, atol=1e-12)
        field = setup.coil_field_per_ampere_t(points)
        np.testing.assert_allclose(
            again.coil_field_per_ampere_t(points), field, rtol=0, atol=1e-13 * np.abs(field).max()
        )
    probe = [0.01, 0.02, -0.03]
    near = setup_from_dict(
        {"preset": "helmholtz", "distance_m": 0.05, "current_limit_a": 2.0, "probe_position_m": probe}
    )
    assert near.coil_field_per_ampere_t(probe)[0, 1] == pytest.approx(on_axis_coil_field_per_ampere(0.05), rel=1e-12)
    with pytest.raises(ValueError, match="exceeds the cap of 2 A"):
        near.currents_a(0.0, 3.0)
    with pytest.raises(ValueError, match="not one of \\['helmholtz', 'largest_spacing'\\]"):
        setup_from_dict({"preset": "pasco"})
    with pytest.raises(ValueError, match="unknown keys \\['distance_cm'\\]"):
        setup_from_dict({"preset": "helmholtz", "distance_cm": 10})


def test_pasco_pairs():
    # Parallel: (4/5)^{3/2}·μ0NI/R along x at the centre; anti-parallel: zero field there.
    scale = scipy.constants.mu_0 * PASCO_TURNS * 0.1 / PASCO_RADIUS_M
    np.testing.assert_allclose(pasco_pair(0.1).field_t([0, 0, 0]), [(4 / 5) ** 1.5 * scale, 0, 0], rtol=1e-14, atol=0)
    assert np.linalg.norm(pasco_pair(0.1, anti=True).field_t([0, 0, 0])) < 1e-15 * scale
