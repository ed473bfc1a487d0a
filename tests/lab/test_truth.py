"""A sweep's decomposition against its scene's truth: the truth at each probe's magnet from the
scene's own sources, written out here (not through the module), and the pulls over them."""

import math

import numpy as np
import pytest

from mows.lab.data.truth import QUANTITIES, Pulls, against_truth, in_plane, in_plane_std, scene_truth
from mows.sim.scenario import load_scenario


def test_the_truth_of_one_probe_is_the_field_and_gradient_at_its_magnet():
    """anti_helmholtz: the Earth's field and the pair's gradient at the centre, where the pair's
    field and its curvature vanish (it is odd about the centre): Bx, By are the Earth's."""
    scene = load_scenario("anti_helmholtz")
    where = scene.pose.magnet_position_m
    field, gradient = scene.environment.source.field_t(where), scene.environment.source.gradient_t_per_m(where)
    truth = scene_truth(scene)
    np.testing.assert_allclose(truth, [field[0], field[1], gradient[0, 0], gradient[0, 1], gradient[1, 1]])
    assert truth[2] == pytest.approx(-2.0 * truth[4], rel=1e-3)  # the pair's axial symmetry: Gxx = −2 Gyy


def test_each_probe_of_a_scene_has_the_truth_its_sweep_determines():
    """The field at each magnet plus (l²/4)·∂²B/∂z² (the curvature over the lever's arc that turns
    with θ0), by a central difference of the field along z."""
    scene = load_scenario("three_probes")
    source = scene.environment.source
    for k, placed in enumerate(scene.placed_probes()):
        where = np.asarray(placed.pose.magnet_position_m, float)
        step = np.array([0.0, 0.0, 1e-4])
        curvature = (source.field_t(where + step) - 2.0 * source.field_t(where) + source.field_t(where - step)) / 1e-8
        field = source.field_t(where) + placed.probe.lever_m**2 / 4.0 * curvature
        gradient = source.gradient_t_per_m(where)
        expected = [field[0], field[1], gradient[0, 0], gradient[0, 1], gradient[1, 1]]
        np.testing.assert_allclose(scene_truth(scene, k), expected, rtol=1e-6, atol=1e-12)


def test_pulls_are_value_less_truth_over_sigma():
    scene = load_scenario("anti_helmholtz")
    truth = scene_truth(scene)
    sigma = np.array([1e-8, 2e-8, 1e-5, 1e-5, 2e-5])
    value = truth + np.array([1.0, -3.0, 0.5, 0.0, 2.5]) * sigma
    components = against_truth(scene, 0, value, sigma)
    assert [c.quantity for c in components] == list(QUANTITIES)
    np.testing.assert_allclose([c.pull for c in components], [1.0, -3.0, 0.5, 0.0, 2.5], atol=1e-9)
    pulls = Pulls.of(components)
    assert (pulls.count, pulls.within, pulls.largest) == (5, 3, pytest.approx(3.0))
    assert pulls.mean_square == pytest.approx((1 + 9 + 0.25 + 0 + 6.25) / 5)
    assert "3 of 5 components within 2σ" in pulls.report()


def test_a_decomposition_s_message_form_reads_the_same():
    field_covariance = np.diag([4e-16, 9e-16])
    gradient_covariance = np.diag([1e-10, 4e-10, 9e-10])
    np.testing.assert_allclose(
        in_plane_std(field_covariance.ravel(), gradient_covariance.ravel()), [2e-8, 3e-8, 1e-5, 2e-5, 3e-5]
    )
    tensor = np.array([[1.0, 2.0, 0.0], [2.0, 3.0, 0.0], [0.0, 0.0, -4.0]])
    np.testing.assert_array_equal(in_plane([5.0, 6.0, 7.0], tensor), in_plane([5.0, 6.0], [1.0, 2.0, 3.0]))


def test_no_components_have_no_pulls():
    pulls = Pulls.of([])
    assert pulls.count == 0 and math.isnan(pulls.largest)
