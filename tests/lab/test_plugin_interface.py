"""A plugin can say what a probe's physics needs: the probe's constants, a per-row change of the
probe's angle, where the magnet sits on the lever, where the pivot is, and parameters that are
off at a value other than 0.

Requirement: each output goes through the full potential as the physics it names. Checked
against closed forms on Eq. 6's components (Bx', Gx'x'), k = U''(0):

- the angle: θ0 → θ0 + Δ in a uniform field B along x gives k = kM + m·B·cos(θ0 + Δ);
- the magnet moved along the lever by a: the field at the magnet is Bx' + Gx'x'·a and the lever
  l + a, U = ½·kM·θ² − m·cos θ·(Bx' + Gx'x'·((l + a)·cos θ − l)), so k = kM + m·(Bx' + Gx'x'·(l + 2a));
- the pivot moved by p (global frame, no curvature): the magnet feels B + G·p, so
  k = kM + m·(x'·(B + G·p) + l·Gx'x');
- a relative stiffness off at 1, written with the probe's kM: k = r·kM + m·Bx';

and, with every component and a curvature, gravity and every offset at once, against a second
implementation written here from the geometry alone (the magnet at p + R(θ0 + θ)·(l + a, c, n),
the moment along the lever, U(θ) = ½·kM·θ² − m·u·B(r) − mass·g·r, the rest angle by scipy's
brentq and U'' by finite differences).
"""

import itertools
import math

import numpy as np
import pytest
import scipy.optimize

from mows.lab import FrequencyModel, MeasurementTable, ProbeSet, catalog, effect
from mows.physics.probe import PAPER_PROBE

PROBE = PAPER_PROBE
KM, M, LEVER = PROBE.spring_nm_per_rad, PROBE.moment_am2, PROBE.lever_m
F00 = PROBE.f00_hz


@effect(name="turned", parameters={"per_rad": (0.0, -1.0, 1.0, "1")})
def turned(rows, per_rad):
    return {"angle_offset_rad": per_rad * rows.theta0_rad}  # a row's own offset: the angle's scale


@effect(
    name="moved_magnet",
    parameters={
        "along_m": (0.0, -1e-3, 1e-3, "m"),
        "across_m": (0.0, -1e-3, 1e-3, "m"),
        "normal_m": (0.0, -1e-3, 1e-3, "m"),
    },
)
def moved_magnet(rows, along_m, across_m, normal_m):
    return {"magnet_offset_m": (along_m, across_m, normal_m)}


@effect(name="moved_pivot", parameters={"x_m": (0.0, -1e-2, 1e-2, "m"), "y_m": (0.0, -1e-2, 1e-2, "m")})
def moved_pivot(rows, x_m, y_m):
    return {"pivot_offset_m": (x_m, y_m)}


@effect(name="spring_ratio", parameters={"ratio": (1.0, 0.5, 2.0, "1")})
def spring_ratio(rows, probe, ratio):
    """The spring is ratio·kM: off at 1, written with the probe's own kM."""
    return {"stiffness_nm_per_rad": (ratio - 1.0) * probe.spring_nm_per_rad}


def _table(theta0_deg, field_t=(0.0, 0.0), gradient_t_per_m=(0.0, 0.0, 0.0)):
    theta = np.asarray(theta0_deg, float)
    n = len(theta)
    columns = {"theta0_deg": theta, "f_hz": np.full(n, F00), "f_std_hz": np.full(n, 1e-3)}
    for name, value in zip(("ref_bx_t", "ref_by_t"), field_t):
        columns[name] = np.full(n, value)
    for name, value in zip(("ref_gxx_t_per_m", "ref_gxy_t_per_m", "ref_gyy_t_per_m"), gradient_t_per_m):
        columns[name] = np.full(n, value)
    return MeasurementTable(columns, "closed form")


def test_a_per_row_angle_offset_turns_each_row_by_its_own_angle():
    theta0 = np.arange(0.0, 360.0, 30.0)
    field_t = 1.2e-3
    per_rad = 0.05  # 0 at θ0 = 0, 18° at 330°
    found = (FrequencyModel(ProbeSet.one(PROBE)) + turned).predict(_table(theta0, (field_t, 0.0)), [F00, per_rad])
    angle = np.radians(theta0) * (1.0 + per_rad)
    np.testing.assert_allclose(found, F00 * np.sqrt(1.0 + M * field_t * np.cos(angle) / KM), rtol=1e-12)
    plain = FrequencyModel(ProbeSet.one(PROBE)).predict(_table(theta0, (field_t, 0.0)), [F00])
    assert np.max(np.abs(found - plain)) > 0.1  # Hz: the offset is there


@pytest.mark.parametrize("along_m", [-4e-4, 3e-4])
def test_a_magnet_moved_along_the_lever_feels_the_field_there_on_a_longer_lever(along_m):
    field_t, gradient = 8e-4, 0.3  # T, T/m along the probe (θ0 = 0)
    table = _table([0.0], (field_t, 0.0), (gradient, 0.0, -gradient))
    found = (FrequencyModel(ProbeSet.one(PROBE)) + moved_magnet).predict(table, [F00, along_m, 0.0, 0.0])
    expected = F00 * math.sqrt(1.0 + M * (field_t + gradient * (LEVER + 2.0 * along_m)) / KM)
    assert found[0] == pytest.approx(expected, rel=1e-12)
    nominal = F00 * math.sqrt(1.0 + M * (field_t + gradient * LEVER) / KM)
    assert abs(found[0] - nominal) > 1e-3  # Hz


def test_a_moved_pivot_puts_the_magnet_where_the_gradient_changes_the_field():
    theta0 = np.array([0.0, 40.0, 135.0, 250.0])
    field, gradient = np.array([6e-4, -3e-4, 0.0]), np.array([[0.2, 0.05, 0.0], [0.05, -0.1, 0.0], [0.0, 0.0, -0.1]])
    pivot = np.array([2e-3, -1.5e-3, 0.0])
    table = _table(theta0, field[:2], (0.2, 0.05, -0.1))
    found = (FrequencyModel(ProbeSet.one(PROBE)) + moved_pivot).predict(table, [F00, *pivot[:2]])
    angle = np.radians(theta0)
    axis = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], -1)
    b_along = axis @ (field + gradient @ pivot)
    g_along = np.einsum("ni,ij,nj->n", axis, gradient, axis)
    np.testing.assert_allclose(found, F00 * np.sqrt(1.0 + M * (b_along + LEVER * g_along) / KM), rtol=1e-12)


def test_a_parameter_off_at_one_with_the_probes_constants():
    table = _table([0.0, 90.0, 180.0], (1e-3, 0.0))
    model = FrequencyModel(ProbeSet.one(PROBE)) + spring_ratio
    np.testing.assert_allclose(
        model.predict(table, [F00, 1.0]), FrequencyModel(ProbeSet.one(PROBE)).predict(table, [F00]), rtol=0
    )
    ratio = 1.03
    b_along = 1e-3 * np.cos(np.radians([0.0, 90.0, 180.0]))
    expected = F00 * np.sqrt(ratio + M * b_along / KM)
    np.testing.assert_allclose(model.predict(table, [F00, ratio]), expected, rtol=1e-12)
    # Fitted from its off value (the default start), the user reads the stiffness as they wrote it.
    truth = _table(np.arange(0.0, 360.0, 30.0), (1e-3, 0.0))
    b_along = 1e-3 * np.cos(np.radians(truth.theta0_deg))
    noise = np.random.default_rng(3).normal(0.0, 1e-3, len(truth))
    truth = truth.with_columns(f_hz=F00 * np.sqrt(ratio + M * b_along / KM) + noise)
    fitted = model.fit(truth).effect_parameters("spring_ratio")[0]
    assert fitted.value == pytest.approx(ratio, abs=4 * fitted.std) and fitted.std < 1e-3


def test_an_effect_that_is_not_off_at_its_off_value_is_refused_in_words():
    @effect(name="always_on", parameters={"ratio": (1.0, 0.5, 2.0, "1")})
    def always_on(rows, ratio):
        return {"stiffness_nm_per_rad": ratio * 1e-7}  # off at 0, not at the declared 1

    with pytest.raises(ValueError, match="always_on .* off values an effect must change nothing"):
        (FrequencyModel(ProbeSet.one(PROBE)) + always_on).predict(_table([0.0]), [F00, 1.0])
    with pytest.raises(ValueError, match="lower ≤ off value ≤ upper"):
        effect(name="outside", parameters={"k": (3.0, 0.5, 2.0, "1")})


def _in_plane_hessian(hxxx, hxxy, hxyy, hyyy):
    """H[i, j, k] = ∂²B_i/∂x_j∂x_k of a curl- and divergence-free field's in-plane part: each
    component depends only on how many indices are y."""
    hessian = np.zeros((3, 3, 3))
    for index in itertools.product((0, 1), repeat=3):
        hessian[index] = (hxxx, hxxy, hxyy, hyyy)[sum(index)]
    return hessian


def _second_implementation_hz(theta0_rad, field, gradient, hessian, gravity, magnet, pivot):
    """f of the probe from the geometry alone: the magnet at p + R(θ0 + θ)·(l + a, c, n) in a
    field B + G·d + ½·H:d d about the nominal magnet position R(θ0)·(l, 0, 0)."""

    def turn(angle):
        c, s = math.cos(angle), math.sin(angle)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    nominal = turn(theta0_rad) @ np.array([LEVER, 0.0, 0.0])
    arm = np.array([LEVER + magnet[0], magnet[1], magnet[2]])

    def energy(theta):
        rotation = turn(theta0_rad + theta)
        position = pivot + rotation @ arm
        d = position - nominal
        b = field + gradient @ d + 0.5 * np.einsum("ijk,j,k->i", hessian, d, d)
        return 0.5 * KM * theta**2 - M * (rotation[:, 0] @ b) - PROBE.magnet_mass_kg * (gravity @ position)

    step = 2e-3

    def torque(theta):
        return -(energy(theta + step / 4) - energy(theta - step / 4)) / (step / 2)

    rest = scipy.optimize.brentq(lambda t: torque(t), -0.3, 0.3, xtol=1e-15)
    stencil = [-energy(rest + 2 * step), 16 * energy(rest + step), -30 * energy(rest), 16 * energy(rest - step)]
    stiffness = (sum(stencil) - energy(rest - 2 * step)) / (12 * step**2)
    return F00 * math.sqrt(stiffness / KM)


@pytest.mark.parametrize("theta0_deg", [0.0, 70.0, 200.0])
def test_every_offset_with_every_component_against_a_second_implementation(theta0_deg):
    field_xy, gradient_xy = (9e-4, -4e-4), (0.25, -0.08, -0.12)
    curvature = (30.0, -12.0, 8.0, 20.0)  # T/m²
    down = (0.02, -0.03)  # in-plane gravity, g
    along, across, normal = 3e-4, -2e-4, 1e-4
    pivot_xy = (1.2e-3, 0.8e-3)
    pool = catalog()
    model = (
        FrequencyModel(ProbeSet.one(PROBE))
        + pool["transverse_gradient"]
        + pool["static_deflection"]
        + pool["field_curvature"]
        + pool["gravity"]
        + moved_magnet
        + moved_pivot
    )
    table = _table([theta0_deg], field_xy, gradient_xy)
    values = [F00, 1.0, 1.0, *curvature, *down, along, across, normal, *pivot_xy]
    found = float(model.predict(table, values)[0])
    gxx, gxy, gyy = gradient_xy
    gradient = np.array([[gxx, gxy, 0.0], [gxy, gyy, 0.0], [0.0, 0.0, -(gxx + gyy)]])
    gravity = 9.80665 * np.array([*down, 0.0])
    expected = _second_implementation_hz(
        math.radians(theta0_deg),
        np.array([*field_xy, 0.0]),
        gradient,
        _in_plane_hessian(*curvature),
        gravity,
        (along, across, normal),
        np.array([*pivot_xy, 0.0]),
    )
    assert found == pytest.approx(expected, rel=1e-9)
    nominal = float(model.predict(table, [F00, 1.0, 1.0, *curvature, *down, 0.0, 0.0, 0.0, 0.0, 0.0])[0])
    assert abs(found - nominal) > 1e-2  # Hz: the offsets move the frequency far beyond the agreement
