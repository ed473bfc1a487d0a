"""The eight-coil navigation system: a field of real sources (loops and dipoles), free of
divergence and curl in the workspace, of the stated strength, within the probe's range."""

import numpy as np

from mows.sim.navigation import coil_axes, navigation_system


def test_the_coils_point_at_the_centre_from_a_hemisphere():
    axes = coil_axes()
    assert axes.shape == (8, 3)
    assert np.allclose(np.linalg.norm(axes, axis=1), 1.0)
    assert np.all(axes[:, 2] <= 1e-12)


def test_the_field_obeys_maxwell_and_stays_in_the_probes_range():
    source = navigation_system(1.5e-3, seed=3)
    assert np.isclose(np.linalg.norm(source.field_t(np.zeros(3))), 1.5e-3)
    rng = np.random.default_rng(0)
    points = rng.uniform(-0.025, 0.025, (30, 3))
    gradient = source.gradient_t_per_m(points)
    scale = np.abs(gradient).max()
    assert np.abs(np.trace(gradient, axis1=1, axis2=2)).max() < 1e-8 * scale
    assert np.abs(gradient - np.swapaxes(gradient, 1, 2)).max() < 1e-8 * scale
    assert np.linalg.norm(source.field_t(points), axis=1).max() < 5e-3  # the probe's ±5 mT
    assert scale < 50e-3  # and ±50 mT/m


def test_winding_errors_differ_between_systems():
    first, second = navigation_system(seed=0), navigation_system(seed=1)
    point = np.array([0.01, 0.02, -0.01])
    assert not np.allclose(first.field_t(point), second.field_t(point), rtol=1e-4)
