"""The arm's pose error carried by the fit: at a surgical arm's 1 mm and 1° the map that
carries it beats the one that ignores it, and its σ stay honest (pulls of sd near 1), where
the ignorant map does not even fit its own sweeps. The sweeps are exact readouts of a
closed-form field (two dipoles) at the true poses, reported at poses off by a draw of the
stated error."""

import math

import numpy as np
import pytest

from mows.workspace.design import boundary_positions
from mows.workspace.fit import fit
from mows.workspace.harmonics import SolidHarmonics
from mows.workspace.poses import PoseError, error_split, fit_with_pose_errors, frame_bound, moved, rotation
from workspace.fields import RADIUS_M, SOURCE, sweeps


def test_a_rotation_vector_turns_about_itself_by_its_length():
    turn = rotation(np.array([0.0, 0.0, math.pi / 2]))
    assert np.allclose(turn @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    assert np.allclose(rotation(np.array([0.3, -0.2, 0.1])) @ [0.3, -0.2, 0.1], [0.3, -0.2, 0.1])


def test_carrying_a_surgical_arms_pose_error_beats_ignoring_it():
    error = PoseError(1e-3, math.radians(1.0))
    basis = SolidHarmonics(5, (0.0, 0.0, 0.0), RADIUS_M)
    points = boundary_positions(30, 0.7 * RADIUS_M)
    truth = SOURCE.field_t(points)
    naive_pulls, carried_pulls, naive_error, carried_error = [], [], [], []
    for seed in range(3):
        rng = np.random.default_rng(20 + seed)
        reported = [moved(obs, rng.normal(size=6) * error.std) for obs in sweeps(25, rng)]
        naive = fit(reported, basis)
        carried = fit_with_pose_errors(reported, basis, error, naive).model
        for model, pulls, errors in ((naive, naive_pulls, naive_error), (carried, carried_pulls, carried_error)):
            field, std = model.field_t(points)
            pulls.append(((field - truth) / std).ravel())
            errors.append(np.sqrt(np.mean((field - truth) ** 2)))
    assert np.mean(carried_error) < 0.5 * np.mean(naive_error)
    # three fits' pulls, correlated within each fit through its few largest pose errors: a wide band
    assert 0.5 < np.std(np.concatenate(carried_pulls)) < 1.5
    # the map that ignores the error does not fit its own sweeps; its σ, widened by that χ²,
    # cover its error only by being wide
    assert naive.chi2_dof > 100


def test_the_frame_bound_is_the_error_of_the_field_shifted_and_turned_by_the_mean_pose_error():
    """A map whose every sweep sat off by the same shift and turn is the true field shifted and
    turned (no fit can tell): over draws of the mean of 30 sweeps' errors its B's rms error is
    the bound. Exact fields at the moved points here, the bound's first-order sums there."""
    error, count = PoseError(1e-3, math.radians(1.0)), 30
    points = boundary_positions(40, 0.8 * RADIUS_M)
    field, gradient = SOURCE.field_t(points), SOURCE.gradient_t_per_m(points)
    rng = np.random.default_rng(7)
    field_error = []
    for _ in range(400):
        shift = rng.normal(size=3) * error.position_std_m / math.sqrt(count)
        turn = rotation(rng.normal(size=3) * error.angle_std_rad / math.sqrt(count))
        field_error.append(np.mean((SOURCE.field_t(points + shift) @ turn.T - field) ** 2))
    # 400 draws of a 6-dimensional error: the mean square known to ~4 %, its root to ~2 %
    bound = frame_bound(field, gradient, error, count)
    assert math.sqrt(np.mean(field_error) / np.mean(field**2)) == pytest.approx(bound, rel=0.08)


def test_the_maps_sigma_splits_into_noise_each_sweeps_pose_error_and_their_mean():
    """The carried map's σ of B, split by cause: the share of the sweeps' mean pose error is the
    frame bound (the fit's covariance holds what no fit can see), and the three shares add up,
    in squares, to the σ the map reports."""
    error = PoseError(1e-4, math.radians(0.01))
    basis = SolidHarmonics(5, (0.0, 0.0, 0.0), RADIUS_M)
    points = boundary_positions(30, 0.7 * RADIUS_M)
    rng = np.random.default_rng(31)
    reported = [moved(obs, rng.normal(size=6) * error.std) for obs in sweeps(25, rng)]
    model = fit_with_pose_errors(reported, basis, error, fit(reported, basis)).model
    split = error_split(reported, model, error, points)
    bound = frame_bound(SOURCE.field_t(points), SOURCE.gradient_t_per_m(points), error, 25)
    rms_field = math.sqrt(np.mean(np.sum(SOURCE.field_t(points) ** 2, axis=1)))
    assert split.field_t["common"] / rms_field == pytest.approx(bound, rel=0.02)
    reported_std = math.sqrt(np.mean(np.sum(model.field_t(points)[1] ** 2, axis=1)))
    assert math.sqrt(sum(v**2 for v in split.field_t.values())) == pytest.approx(reported_std, rel=0.02)
    assert all(v > 0 for v in (*split.field_t.values(), *split.gradient_t_per_m.values()))
