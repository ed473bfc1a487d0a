"""The truth a rotation sweep is compared with: the field at the magnet plus (l²/4)·∂²B/∂z² and
the gradient there (docs/multi_probe.md), checked against central differences of the field
itself, not of the sources' Hessians."""

import numpy as np

from mows.lab import swept_reference_at
from mows.physics.sources import UniformField
from mows.sim.scenario import load_scenario

STEP_M = 2e-4  # small enough that the difference's truncation, (h²/12)·∂⁴B/∂z⁴, is below 0.2 pT here


def test_the_curvature_term_is_the_central_difference_of_the_field_along_z():
    scene = load_scenario("three_probes")
    source = scene.environment.source
    for placed in scene.placed_probes():
        where = np.asarray(placed.pose.magnet_position_m, float)
        up = np.array([0.0, 0.0, STEP_M])
        second = (source.field_t(where + up) - 2.0 * source.field_t(where) + source.field_t(where - up)) / STEP_M**2
        lever = placed.probe.lever_m
        field, gradient = swept_reference_at(source, where, lever)
        expected = source.field_t(where) + lever**2 / 4.0 * second
        # The difference agrees to its truncation and rounding errors (< 0.2 pT of a ~30 nT term).
        assert np.max(np.abs(field - expected)) < 1e-12
        assert np.max(np.abs(field - source.field_t(where))) > 1e-8  # the term is tens of nT, not nothing
        np.testing.assert_array_equal(gradient, source.gradient_t_per_m(where))


def test_a_uniform_field_has_no_curvature_to_add():
    source = UniformField([20e-6, -5e-6, 40e-6])
    field, gradient = swept_reference_at(source, (0.01, 0.02, 0.0), 2e-3)
    np.testing.assert_array_equal(field, [20e-6, -5e-6, 40e-6])
    assert not gradient.any()
