"""The next best pose: sweeps chosen one by one for the largest gain leave the map less
uncertain than as many sweeps at poses drawn at random from the same reachable set, by the
D criterion (the coefficients' log det) and the I criterion (mean predicted σ of B over the
workspace), each judged by the other's measure too."""

import numpy as np
import pytest

from mows.physics.probe import PAPER_PROBE
from mows.workspace.design import candidate_designs, gains, next_best, random_rotation
from mows.workspace.harmonics import SolidHarmonics
from mows.workspace.observations import gravity_field_t, plane_readout
from mows.workspace.simulated import ball_points

RADIUS_M = 0.025
COVARIANCE = np.diag([50e-9, 50e-9, 20e-6, 20e-6, 20e-6]) ** 2
SWEEPS = 12


def _candidates(rng):
    weight = gravity_field_t(PAPER_PROBE, (0.0, 0.0, -9.80665))
    return [
        (p, plane_readout(random_rotation(rng)[:2], PAPER_PROBE.lever_m, weight))
        for p in ball_points(150, RADIUS_M, rng)
    ]


def _information_after(designs, chosen, basis):
    info = np.eye(basis.size)
    for index in chosen:
        info += designs[index].T @ np.linalg.solve(COVARIANCE, designs[index])
    return info


def _mean_field_variance(info, basis, points):
    field_design = basis.design(points, 0).reshape(-1, basis.size)
    return float(np.mean(np.einsum("ij,jk,ik->i", field_design, np.linalg.inv(info), field_design)))


@pytest.mark.parametrize("criterion", ["D", "I"])
def test_chosen_sweeps_beat_random_ones(criterion):
    rng = np.random.default_rng(8)
    basis = SolidHarmonics(3, (0.0, 0.0, 0.0), RADIUS_M)
    designs = candidate_designs(basis, _candidates(rng))
    points = ball_points(60, RADIUS_M, rng)
    chosen: list[int] = []
    for _ in range(SWEEPS):
        chosen.append(
            next_best(basis, _information_after(designs, chosen, basis), designs, COVARIANCE, criterion, points)
        )
    best = _information_after(designs, chosen, basis)
    for _ in range(5):
        drawn = _information_after(designs, rng.choice(len(designs), SWEEPS, replace=False), basis)
        assert np.linalg.slogdet(best)[1] > np.linalg.slogdet(drawn)[1]
        assert _mean_field_variance(best, basis, points) < _mean_field_variance(drawn, basis, points)


def test_a_pose_already_measured_gains_less_the_second_time():
    rng = np.random.default_rng(9)
    basis = SolidHarmonics(2, (0.0, 0.0, 0.0), RADIUS_M)
    designs = candidate_designs(basis, _candidates(rng)[:5])
    before = gains(basis, np.eye(basis.size), designs, COVARIANCE)
    after = gains(basis, _information_after(designs, [0], basis), designs, COVARIANCE)
    assert after[0] < 0.5 * before[0]
    with pytest.raises(ValueError, match="reach"):
        next_best(basis, np.eye(basis.size), [], COVARIANCE)
