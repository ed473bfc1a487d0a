"""Field sources against Maxwell's equations, textbook formulas and Biot–Savart quadrature."""

import numpy as np
import pytest
import scipy.constants
from scipy import integrate

from mows.physics.field import (
    CurrentLoop,
    LinearGradient,
    PointDipole,
    SumSource,
    UniformField,
    anti_helmholtz_pair,
    helmholtz_pair,
    solenoid,
    source_from_dict,
    source_to_dict,
)

MU0 = scipy.constants.mu_0  # T·m/A (CODATA 2022 in scipy 1.17)
RNG = np.random.default_rng(20240611)

# A loop with a tilted axis away from the origin, so that no frame is special.
LOOP = CurrentLoop(center_m=[0.01, -0.02, 0.005], axis=[1.0, 2.0, 2.0], radius_m=0.05, turns=7, current_a=1.3)
NI = LOOP.turns * LOOP.current_a


def loop_frame(loop):
    """Unit vectors e1, e2 in the loop plane (e1 × e2 = axis)."""
    e1 = np.cross(loop.axis, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(loop.axis, e1)


def loop_point(loop, rho_m, z_m, phi_rad=0.3):
    e1, e2 = loop_frame(loop)
    return loop.center_m + rho_m * (np.cos(phi_rad) * e1 + np.sin(phi_rad) * e2) + z_m * loop.axis


def wire_distance_m(loop, points):
    rel = points - loop.center_m
    z = rel @ loop.axis
    rho = np.linalg.norm(rel - z[..., None] * loop.axis, axis=-1)
    return np.hypot(rho - loop.radius_m, z)


def biot_savart(loop, point, order):
    """Field (order 0), gradient (1) or Hessian (2) of the loop by adaptive quadrature of the
    (differentiated) Biot–Savart kernel (μ0/4π)·N·I·dl × d/|d|³ around the wire."""
    e1, e2 = loop_frame(loop)
    eye = np.eye(3)

    def kernel(phi):
        dl = loop.radius_m * (-np.sin(phi) * e1 + np.cos(phi) * e2)
        d = point - loop.center_m - loop.radius_m * (np.cos(phi) * e1 + np.sin(phi) * e2)
        r = np.linalg.norm(d)
        if order == 0:
            v = d / r**3
        elif order == 1:  # ∂_j (d_i/r³)
            v = eye / r**3 - 3 * np.outer(d, d) / r**5
        else:  # ∂_j ∂_k (d_i/r³)
            v = (
                -3
                * (np.einsum("ij,k->ijk", eye, d) + np.einsum("ik,j->ijk", eye, d) + np.einsum("i,jk->ijk", d, eye))
                / r**5
                + 15 * np.einsum("i,j,k->ijk", d, d, d) / r**7
            )
        return np.cross(dl.reshape((3,) + (1,) * order), v, axis=0).ravel()

    value, _ = integrate.quad_vec(kernel, 0, 2 * np.pi, epsabs=0, epsrel=1e-13, limit=1000)
    return MU0 / (4 * np.pi) * loop.turns * loop.current_a * value.reshape((3,) * (order + 1))


# ---------------------------------------------------------------- Maxwell for every source

SOURCES = {
    "uniform": UniformField([1e-5, -2e-5, 4e-5]),
    "linear_gradient": LinearGradient(
        [[1e-3, 2e-4, 0], [2e-4, -3e-4, 5e-4], [0, 5e-4, -7e-4]], [0.01, 0, 0], [0, 1e-6, 0]
    ),
    "dipole": PointDipole([3e-4, -1e-4, 2e-4], [0.2, 0.1, -0.1]),
    "loop": LOOP,
    "helmholtz": helmholtz_pair([0, 0.01, 0], [0, 0, 1], 0.08, 20, 0.5),
    "anti_helmholtz": anti_helmholtz_pair([0.02, 0, 0], [1, 1, 0], 0.06, 10, 0.7),
    "solenoid": solenoid([0, 0, -0.03], [0, 1, 0], 0.025, 0.02, 200, 1.0, n_loops=4),
    "scaled_sum": (PointDipole([0, 0, 1e-3], [0, 0, 0.3]) + LOOP).scaled(-2.5),
}


def random_points(n=12):
    """Points in a 10 cm box, none within 5 mm of any wire or dipole above."""
    points = RNG.uniform(-0.1, 0.1, size=(4 * n, 3))
    loops = [s for src in SOURCES.values() for s in getattr(src, "sources", [src]) if isinstance(s, CurrentLoop)]
    clear = np.all([wire_distance_m(lp, points) > 5e-3 for lp in loops], axis=0)
    clear &= np.linalg.norm(points - [0.2, 0.1, -0.1], axis=-1) > 5e-3
    return points[clear][:n]


POINTS = random_points()


@pytest.mark.parametrize("name", SOURCES)
def test_gradient_is_symmetric_and_traceless(name):
    # ∇·B = tr G = 0 and ∇×B = 0 ⇔ G = Gᵀ, at points off the sources.
    g = SOURCES[name].gradient_t_per_m(POINTS)
    scale = np.linalg.norm(g, axis=(-2, -1)) + 1e-30
    assert np.all(np.abs(np.trace(g, axis1=-2, axis2=-1)) <= 1e-9 * scale)
    assert np.all(np.linalg.norm(g - np.swapaxes(g, -1, -2), axis=(-2, -1)) <= 1e-9 * scale)


@pytest.mark.parametrize("name", SOURCES)
def test_hessian_is_fully_symmetric_and_harmonic(name):
    # H_ijk = ∂_k G_ij: symmetric in j,k (mixed partials), in i,j (curl-free); ∇²B_i = H_ijj = 0.
    h = SOURCES[name].hessian_t_per_m2(POINTS[:6])
    scale = np.linalg.norm(h.reshape(len(h), -1), axis=-1)[:, None, None, None] + 1e-30
    assert np.all(np.abs(h - np.swapaxes(h, -1, -2)) <= 5e-8 * scale)
    assert np.all(np.abs(h - np.swapaxes(h, -3, -2)) <= 5e-8 * scale)
    assert np.all(np.abs(np.einsum("...ijj->...i", h)) <= 5e-8 * scale[..., 0, 0])


def central_difference(func, points, step_m):
    """4th-order central difference of func along x, y, z (test-side, independent)."""
    out = []
    for j in range(3):
        e = np.zeros(3)
        e[j] = step_m
        out.append(
            (8 * (func(points + e) - func(points - e)) - (func(points + 2 * e) - func(points - 2 * e))) / (12 * step_m)
        )
    return np.stack(out, axis=-1)


@pytest.mark.parametrize("name", SOURCES)
def test_derivatives_match_finite_differences(name):
    source = SOURCES[name]
    points = POINTS[:4]
    g = source.gradient_t_per_m(points)
    h = source.hessian_t_per_m2(points)
    g_fd = central_difference(source.field_t, points, 1e-4)
    h_fd = central_difference(source.gradient_t_per_m, points, 1e-4)
    assert np.allclose(g, g_fd, rtol=0, atol=1e-7 * np.abs(g).max() + 1e-20)
    assert np.allclose(h, h_fd, rtol=0, atol=1e-6 * np.abs(h).max() + 1e-20)


def test_points_shape_is_vectorised_and_checked():
    grid = RNG.uniform(0.2, 0.3, size=(2, 5, 3))
    for source in SOURCES.values():
        assert source.field_t(grid).shape == (2, 5, 3)
        assert source.gradient_t_per_m(grid).shape == (2, 5, 3, 3)
        assert np.allclose(source.field_t(grid)[1, 3], source.field_t(grid[1, 3]), rtol=1e-14, atol=0)
    with pytest.raises(ValueError, match="shape"):
        LOOP.field_t([1.0, 2.0])


# ---------------------------------------------------------------- dipole and constant gradient


def test_dipole_on_axis_and_equator():
    m, r = 2e-3, 0.07
    dipole = PointDipole([0, 0, m], [0, 0, 0])
    k = MU0 * m / (4 * np.pi * r**3)
    assert np.allclose(dipole.field_t([0, 0, r]), [0, 0, 2 * k], rtol=1e-12)
    assert np.allclose(dipole.field_t([r, 0, 0]), [0, 0, -k], rtol=1e-12)
    # d/dz of 2μ0m/(4πz³) on the axis
    assert dipole.gradient_t_per_m([0, 0, r])[2, 2] == pytest.approx(-6 * k / r, rel=1e-12)
    assert dipole.hessian_t_per_m2([0, 0, r])[2, 2, 2] == pytest.approx(24 * k / r**2, rel=1e-12)
    with pytest.raises(ValueError, match="dipole"):
        dipole.field_t([0, 0, 0])


def test_linear_gradient_refuses_fields_that_break_maxwell():
    with pytest.raises(ValueError, match="not symmetric"):
        LinearGradient([[0, 1e-3, 0], [0, 0, 0], [0, 0, 0]])
    with pytest.raises(ValueError, match="not traceless"):
        LinearGradient(np.diag([1e-3, 1e-3, 0]))
    g = np.array([[1, 2, 0], [2, -3, 0], [0, 0, 2]]) * 1e-3
    source = LinearGradient(g, origin_m=[0.1, 0, 0], field_at_origin_t=[0, 0, 5e-5])
    assert np.allclose(source.field_t([0.2, 0.1, 0]), [0, 0, 5e-5] + g @ [0.1, 0.1, 0], rtol=1e-14)


# ---------------------------------------------------------------- current loop


def test_loop_on_axis_field_and_its_derivatives():
    # B_z(z) = μ0NIR²/(2(R²+z²)^{3/2}); dB_z/dz = −3μ0NIR²z/(2(R²+z²)^{5/2});
    # d²B_z/dz² = 3μ0NIR²(4z² − R²)/(2(R²+z²)^{7/2}).
    R = LOOP.radius_m
    for z in [0.0, 0.3 * R, -1.7 * R, 6 * R]:
        point = LOOP.center_m + z * LOOP.axis
        a = LOOP.axis
        assert LOOP.field_t(point) == pytest.approx(MU0 * NI * R**2 / (2 * (R**2 + z**2) ** 1.5) * a, rel=1e-13)
        dbz = -3 * MU0 * NI * R**2 * z / (2 * (R**2 + z**2) ** 2.5)
        d2bz = 3 * MU0 * NI * R**2 * (4 * z**2 - R**2) / (2 * (R**2 + z**2) ** 3.5)
        local = MU0 * NI / (R**2 + z**2)  # |B|/s scale of the derivative
        assert a @ LOOP.gradient_t_per_m(point) @ a == pytest.approx(dbz, abs=1e-10 * local)
        assert np.einsum("ijk,i,j,k->", LOOP.hessian_t_per_m2(point), a, a, a) == pytest.approx(
            d2bz, abs=1e-8 * local / R
        )
    assert np.linalg.norm(LOOP.field_t(LOOP.center_m)) == pytest.approx(MU0 * NI / (2 * R), rel=1e-14)


def test_loop_gradient_on_axis_is_axisymmetric():
    # On the axis G = diag(−Gzz/2, −Gzz/2, Gzz) in the loop frame (symmetry + ∇·B = 0).
    e1, e2 = loop_frame(LOOP)
    g = LOOP.gradient_t_per_m(LOOP.center_m + 0.4 * LOOP.radius_m * LOOP.axis)
    frame = np.stack([e1, e2, LOOP.axis])
    local = frame @ g @ frame.T
    gzz = local[2, 2]
    assert np.allclose(local, np.diag([-gzz / 2, -gzz / 2, gzz]), rtol=0, atol=1e-10 * abs(gzz))


@pytest.mark.parametrize("rho_over_r, z_over_r", [(0.3, 0.2), (0.95, 0.05), (1.2, -0.4), (2.5, 1.0), (0.999, 1e-3)])
def test_loop_matches_biot_savart_off_axis(rho_over_r, z_over_r):
    R = LOOP.radius_m
    point = loop_point(LOOP, rho_over_r * R, z_over_r * R)
    s = wire_distance_m(LOOP, point)
    b = biot_savart(LOOP, point, 0)
    scale = np.linalg.norm(b)
    assert np.linalg.norm(LOOP.field_t(point) - b) <= 1e-9 * scale
    # Derivatives are finite differences with steps ∝ s: errors relative to |B|/s, |B|/s².
    assert np.linalg.norm(LOOP.gradient_t_per_m(point) - biot_savart(LOOP, point, 1)) <= 1e-10 * scale / s
    assert np.linalg.norm(LOOP.hessian_t_per_m2(point) - biot_savart(LOOP, point, 2)) <= 3e-8 * scale / s**2


def test_loop_far_field_is_its_dipole():
    # Outside r > R the loop is a dipole m = NIπR² plus an octupole; on the axis
    # B/B_dip = (1 + R²/z²)^{-3/2} = 1 − 1.5(R/r)² + …, and 1.5(R/r)² bounds the octupole
    # (|P3-field| is largest on the axis), so the relative difference at r is ≤ 1.5(R/r)²(1 + 2(R/r)²).
    R = LOOP.radius_m
    dipole = PointDipole(NI * np.pi * R**2 * LOOP.axis, LOOP.center_m)
    directions = RNG.normal(size=(40, 3))
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    for r in [100 * R, 300 * R]:
        bound = 1.5 * (R / r) ** 2 * (1 + 2 * (R / r) ** 2)
        points = LOOP.center_m + r * directions
        b_dip = dipole.field_t(points)
        error = np.linalg.norm(LOOP.field_t(points) - b_dip, axis=-1) / np.linalg.norm(b_dip, axis=-1)
        assert np.all(error <= bound)
        assert error.max() > 0.5 * bound  # it is the octupole, not noise
        assert np.linalg.norm(LOOP.gradient_t_per_m(points[:4]) - dipole.gradient_t_per_m(points[:4])) <= 4 * (
            R / r
        ) ** 2 * np.linalg.norm(dipole.gradient_t_per_m(points[:4]))
        assert np.linalg.norm(LOOP.hessian_t_per_m2(points[:2]) - dipole.hessian_t_per_m2(points[:2])) <= 6 * (
            R / r
        ) ** 2 * np.linalg.norm(dipole.hessian_t_per_m2(points[:2]))


def test_loop_refuses_points_on_the_wire():
    with pytest.raises(ValueError, match="wire"):
        LOOP.field_t(loop_point(LOOP, LOOP.radius_m, 0.0))


# ---------------------------------------------------------------- pairs and solenoid

R_PAIR, N_PAIR, I_PAIR = 0.105, 200, 0.1


def test_helmholtz_centre_field_and_fourth_order_flatness():
    pair = helmholtz_pair([0, 0, 0], [1, 0, 0], R_PAIR, N_PAIR, I_PAIR)
    b0 = (4 / 5) ** 1.5 * MU0 * N_PAIR * I_PAIR / R_PAIR
    assert pair.field_t([0, 0, 0]) == pytest.approx([b0, 0, 0], rel=1e-14, abs=1e-20)
    # On the axis: B(x)/B0 = 1 − (144/125)(x/R)⁴ + O((x/R)⁶), the (x/R)² term cancels.
    x = 0.05 * R_PAIR
    deviation = pair.field_t([x, 0, 0])[0] / b0 - 1
    assert deviation == pytest.approx(-144 / 125 * (x / R_PAIR) ** 4, rel=0.01)
    # In a ball of radius a the fourth-order term bounds |B − B0|/B0 by (144/125)(a/R)⁴
    # (max over angles of |(P4, P4¹/5)| is 1, on the axis); a = R/20 gives 7.2e-6 < 1e-4.
    a = 0.05 * R_PAIR
    ball = RNG.normal(size=(200, 3))
    ball *= a * RNG.uniform(0, 1, size=(200, 1)) ** (1 / 3) / np.linalg.norm(ball, axis=-1, keepdims=True)
    variation = np.linalg.norm(pair.field_t(ball) - [b0, 0, 0], axis=-1) / b0
    assert variation.max() <= 144 / 125 * (a / R_PAIR) ** 4 * 1.05


def test_anti_helmholtz_centre_gradient():
    # dBx/dx = 3μ0NIR²d/(2(R² + d²/4)^{5/2}) with d = R: 48/(25√5)·μ0NI/R².
    pair = anti_helmholtz_pair([0, 0, 0], [1, 0, 0], R_PAIR, N_PAIR, I_PAIR)
    scale = MU0 * N_PAIR * I_PAIR / R_PAIR
    assert np.linalg.norm(pair.field_t([0, 0, 0])) <= 1e-15 * scale
    g = pair.gradient_t_per_m([0, 0, 0])
    gxx = 48 / (25 * np.sqrt(5)) * scale / R_PAIR
    assert gxx == pytest.approx(3 * MU0 * N_PAIR * I_PAIR * R_PAIR**3 / (2 * (1.25 * R_PAIR**2) ** 2.5), rel=1e-14)
    assert np.allclose(g, np.diag([gxx, -gxx / 2, -gxx / 2]), rtol=0, atol=1e-10 * gxx)


def test_long_solenoid_approaches_a_current_sheet():
    # Centre field of a uniform sheet: μ0·N·I/√(L² + 4R²); the midpoint stack of n loops
    # differs by O((L/n)²/R²) — here (L/n)/R = 1/40.
    R, L, N, current_a = 0.01, 0.1, 1000, 0.2
    coil = solenoid([0, 0, 0], [0, 0, 1], R, L, N, current_a, n_loops=400)
    assert coil.field_t([0, 0, 0])[2] == pytest.approx(MU0 * N * current_a / np.sqrt(L**2 + 4 * R**2), rel=2e-4)


# ---------------------------------------------------------------- composition and YAML form


def assert_same_field(a, b):
    """Equal to rounding, relative to the largest component."""
    np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * np.abs(b).max())


def test_superposition_and_scaling_are_linear():
    a, b = SOURCES["dipole"], SOURCES["loop"]
    assert_same_field((a + b).field_t(POINTS), a.field_t(POINTS) + b.field_t(POINTS))
    assert_same_field(b.scaled(-3.0).field_t(POINTS), -3.0 * b.field_t(POINTS))
    assert_same_field(sum([a, b, a]).field_t(POINTS), 2 * a.field_t(POINTS) + b.field_t(POINTS))
    assert np.all(SumSource().field_t(POINTS) == 0)


@pytest.mark.parametrize("name", SOURCES)
def test_dict_round_trip_gives_the_same_field(name):
    source = SOURCES[name]
    assert_same_field(source_from_dict(source_to_dict(source)).field_t(POINTS), source.field_t(POINTS))


def test_dict_form_is_si_and_strict():
    pair = source_from_dict(
        {
            "type": "helmholtz",
            "center_m": [0, 0, 0],
            "axis": [1, 0, 0],
            "radius_m": R_PAIR,
            "turns": N_PAIR,
            "current_a": I_PAIR,
        }
    )
    assert pair.field_t([0, 0, 0])[0] == pytest.approx((4 / 5) ** 1.5 * MU0 * N_PAIR * I_PAIR / R_PAIR, rel=1e-14)
    with pytest.raises(ValueError, match="not one of.*dipole"):
        source_from_dict({"type": "magnet"})
    with pytest.raises(ValueError, match="unknown keys \\['field_ut'\\].*allowed keys are \\['field_t'\\]"):
        source_from_dict({"type": "uniform", "field_ut": [0, 0, 1]})
    with pytest.raises(ValueError, match="missing keys \\['radius_m'"):
        source_from_dict({"type": "loop", "center_m": [0, 0, 0], "axis": [0, 0, 1], "turns": 1, "current_a": 1})
