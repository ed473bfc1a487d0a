"""The workspace fit: weighted least squares whose σ are honest (pulls of sd 1 over a Monte
Carlo sized to resolve 0.8-1.2), whose cross-validation picks a degree that holds the field,
and that refuses what its observations cannot determine.

The observations here are exact readouts of a field of closed form (two point dipoles outside
the workspace, mows.physics.sources) with Gaussian noise of their stated covariance: the fit is
tested against the physics, not against itself."""

import numpy as np
import pytest

from mows.physics.probe import PAPER_PROBE
from mows.workspace.design import boundary_positions
from mows.workspace.fit import choose_degree, fit, whitened_rows
from mows.workspace.harmonics import SolidHarmonics
from mows.workspace.observations import Observation, gravity_field_t, hall_observation
from mows.workspace.tool import wrench
from workspace.fields import RADIUS_M, SOURCE, sweeps


def test_the_field_is_its_sources_and_the_pulls_are_honest():
    rng = np.random.default_rng(3)
    points = boundary_positions(60, 0.8 * RADIUS_M)
    truth = SOURCE.field_t(points)
    pulls, chi2 = [], []
    for _ in range(15):
        model = fit(sweeps(30, rng), SolidHarmonics(6, (0.0, 0.0, 0.0), RADIUS_M))
        field, std = model.field_t(points)
        pulls.append(((field - truth) / std).ravel())
        chi2.append(model.chi2_dof)
    # 15 fits × 60 points × 3 components, correlated within a fit: the sd is known to ~5 %
    assert 0.9 < np.std(np.concatenate(pulls)) < 1.1
    assert 0.9 < np.mean(chi2) < 1.1


def test_a_map_that_forgets_the_magnets_weight_is_off_by_its_field():
    """Gravity on the lever is a uniform field to the sweep, B_g = (a·l/m)·g, 154 µT: no fit can
    tell it from the map's own field, so only the readout's offset keeps it out of the map."""
    observations = sweeps(30, np.random.default_rng(4))
    weightless = sweeps(30, np.random.default_rng(4), gravity=(0.0, 0.0, 0.0))
    forgetful = [
        Observation(o.position_m, o.plane, o.values, o.covariance, w.readout, o.group, o.components)
        for o, w in zip(observations, weightless)
    ]
    points = boundary_positions(10, 0.5 * RADIUS_M)
    truth = SOURCE.field_t(points)
    basis = SolidHarmonics(6, (0.0, 0.0, 0.0), RADIUS_M)
    field, std = fit(observations, basis).field_t(points)
    assert np.all(np.abs(field - truth) < 5 * std)
    offset = fit(forgetful, basis).field_t(points)[0] - truth
    weight_field = gravity_field_t(PAPER_PROBE, (0.0, 0.0, -9.80665))
    assert np.allclose(offset, weight_field, rtol=0, atol=0.01 * np.linalg.norm(weight_field))


def test_cross_validation_rejects_a_degree_too_low_for_the_field():
    choice = choose_degree(sweeps(30, np.random.default_rng(5)), range(1, 8), scale_m=RADIUS_M)
    assert choice.chosen >= 4
    scores = dict(zip(choice.degrees, choice.scores))
    assert scores[1] > 100 * scores[choice.chosen]


def test_too_few_poses_are_refused_with_the_reason():
    with pytest.raises(ValueError, match="cannot determine"):
        fit(sweeps(5, np.random.default_rng(6)), SolidHarmonics(5, (0.0, 0.0, 0.0), RADIUS_M))
    hall_on_a_line = [
        hall_observation([0.001 * k, 0.0, 0.0], [1e-3, 0.0, 0.0], np.eye(3) * 1e-12, k) for k in range(30)
    ]
    with pytest.raises(ValueError, match="undetermined"):
        fit(hall_on_a_line, SolidHarmonics(3, (0.0, 0.0, 0.0), RADIUS_M))


def test_force_and_torque_on_a_tool_follow_the_energy_of_its_moment():
    model = fit(sweeps(30, np.random.default_rng(7)), SolidHarmonics(6, (0.0, 0.0, 0.0), RADIUS_M))
    moment = np.array([0.0, 0.05, 0.02])  # a capsule's magnet, A·m²
    points = np.array([[0.01, -0.005, 0.008], [-0.015, 0.0, 0.0]])
    result = wrench(model, points, moment)
    step = 1e-6
    energy_gradient = np.stack(
        [
            (SOURCE.field_t(points + step * e) @ moment - SOURCE.field_t(points - step * e) @ moment) / (2 * step)
            for e in np.eye(3)
        ],
        axis=1,
    )  # F = ∇(m·B)
    assert np.all(np.abs(result.force_n - energy_gradient) < 5 * result.force_std_n + 1e-12)
    torque = np.cross(moment, SOURCE.field_t(points))
    assert np.all(np.abs(result.torque_nm - torque) < 5 * result.torque_std_nm)
    assert np.all(result.force_std_n > 0) and np.all(result.torque_std_nm > 0)


def test_a_map_that_does_not_fit_its_data_widens_its_sigma_by_its_chi2():
    observations = sweeps(30, np.random.default_rng(10))
    basis = SolidHarmonics(3, (0.0, 0.0, 0.0), RADIUS_M)  # too low for the dipoles: χ²/dof ≫ 1
    model = fit(observations, basis)
    assert model.chi2_dof > 10
    design = np.concatenate([whitened_rows(basis, obs)[0] for obs in observations])
    assert np.allclose(model.covariance, np.linalg.inv(design.T @ design) * model.chi2_dof, rtol=1e-6)
