"""The solid-harmonic potential obeys Maxwell whatever its coefficients, and represents the
fields of sources outside its ball: uniform and linear fields exactly at degrees 1 and 2, a
point dipole's (closed form, mows.physics.sources) with an error that falls geometrically with
the degree, as the multipole expansion's terms fall as (r/R)^n."""

import numpy as np
import pytest

from mows.physics.field import LinearGradient, PointDipole, UniformField
from mows.workspace.harmonics import SolidHarmonics, coefficient_count, harmonic_basis

RADIUS_M = 0.025


def test_each_degree_has_2n_plus_1_harmonic_polynomials():
    assert [harmonic_basis(n).shape[1] for n in range(1, 9)] == [2 * n + 1 for n in range(1, 9)]
    assert coefficient_count(6) == 48


def test_any_coefficients_give_a_field_without_divergence_or_curl():
    basis = SolidHarmonics(7, (0.01, 0.0, -0.005), RADIUS_M)
    rng = np.random.default_rng(1)
    points = rng.uniform(-RADIUS_M, RADIUS_M, (20, 3))
    coefficients = rng.normal(size=basis.size) * 1e-3
    gradient = basis.design(points, 1) @ coefficients
    hessian = basis.design(points, 2) @ coefficients
    scale = np.abs(gradient).max()
    assert np.abs(np.trace(gradient, axis1=1, axis2=2)).max() < 1e-12 * scale
    assert np.abs(gradient - np.swapaxes(gradient, 1, 2)).max() < 1e-12 * scale
    assert np.abs(np.einsum("nijj->ni", hessian)).max() < 1e-12 * np.abs(hessian).max()


def test_the_gradient_design_is_the_derivative_of_the_field_design():
    basis = SolidHarmonics(5, (0.0, 0.0, 0.0), RADIUS_M)
    point = np.array([[0.004, -0.011, 0.007]])
    step = 1e-6
    for axis in range(3):
        offset = np.eye(3)[axis] * step
        numeric = (basis.design(point + offset, 0) - basis.design(point - offset, 0)) / (2 * step)
        assert np.allclose(numeric, basis.design(point, 1)[:, :, axis], rtol=1e-6, atol=1e-9)


def _least_squares_error(source, degree):
    basis = SolidHarmonics(degree, (0.0, 0.0, 0.0), RADIUS_M)
    rng = np.random.default_rng(2)
    points = rng.normal(size=(200, 3))
    points = RADIUS_M * points / np.linalg.norm(points, axis=1)[:, None] * rng.uniform(0, 1, (200, 1)) ** (1 / 3)
    design = basis.design(points, 0).reshape(-1, basis.size)
    truth = source.field_t(points).reshape(-1)
    coefficients, *_ = np.linalg.lstsq(design, truth, rcond=None)
    return np.sqrt(np.mean((design @ coefficients - truth) ** 2) / np.mean(truth**2))


def test_uniform_and_linear_fields_are_exact_at_degrees_1_and_2():
    gradient = np.array([[2.0, 1.0, 0.5], [1.0, -3.0, 0.2], [0.5, 0.2, 1.0]]) * 1e-2
    assert _least_squares_error(UniformField([1e-3, -2e-3, 5e-4]), 1) < 1e-12
    assert _least_squares_error(LinearGradient(gradient, [0.0, 0.0, 0.0], [1e-3, 0.0, 0.0]), 2) < 1e-12


@pytest.mark.parametrize("distance_m", [0.08, 0.12])
def test_a_dipole_outside_the_ball_converges_as_its_multipole_series(distance_m):
    dipole = PointDipole([0.3, -1.0, 0.5], [distance_m * 0.6, distance_m * 0.8, 0.0])
    errors = np.array([_least_squares_error(dipole, degree) for degree in (2, 4, 6, 8)])
    ratio = RADIUS_M / distance_m
    assert np.all(np.diff(np.log(errors)) < 0)
    # each two degrees gain about (r/R)²: allow a factor 3 either way for the (n + 1) prefactors
    gains = errors[1:] / errors[:-1]
    assert np.all(gains < 3 * ratio**2) and np.all(gains > ratio**2 / 3)
