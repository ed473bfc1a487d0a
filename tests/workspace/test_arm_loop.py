"""The whole core path of a workspace map: a simulated CRTK arm carries the probe to poses the
map chooses (D-optimal among reachable candidates), the probe sweeps where the arm truly put it
in an eight-coil field from Biot–Savart, the sweep's own decomposition reports B and G, each
sweep enters the map at the pose the arm reported, and the fit carries the arm's stated
accuracy. The map's predictions land within 2σ of the truth at held-out points."""

import math

import numpy as np
import pytest

from mows.physics.probe import PAPER_PROBE
from mows.sim.navigation import navigation_system
from mows.workspace.arm import NS_PER_S, Reach, SimulatedArm, StampedPose, matrix_quaternion, pose_problem
from mows.workspace.design import candidate_designs, information, next_best
from mows.workspace.fit import choose_degree, fit
from mows.workspace.harmonics import SolidHarmonics
from mows.workspace.observations import gravity_field_t, plane_readout
from mows.workspace.poses import PoseError, fit_with_pose_errors
from mows.workspace.simulated import (
    GRAVITY_M_PER_S2,
    SweepPose,
    ball_points,
    random_rotation,
    simulate_sweep,
    sweep_observations,
)

RADIUS_M = 0.015  # a 3 cm workspace: twelve sweeps hold its field to degree 5
SWEEPS = 12
ACCURACY = PoseError(1e-4, math.radians(0.01))  # an industrial arm's
SWEEP_COVARIANCE = np.diag([0.1e-6, 0.1e-6, 30e-6, 30e-6, 30e-6]) ** 2  # what a sweep is expected to give


@pytest.mark.slow
def test_mapper_chosen_poses_give_a_map_within_two_sigma():
    rng = np.random.default_rng(12)
    source = navigation_system(1.5e-3, seed=2)
    arm = SimulatedArm(rng, ACCURACY, PoseError(1e-6, 1e-6), Reach(), latency_s=0.02)
    rotations = [random_rotation(rng) for _ in range(120)]
    positions = ball_points(120, RADIUS_M, rng)
    weight = gravity_field_t(PAPER_PROBE, GRAVITY_M_PER_S2)
    design_basis = SolidHarmonics(4, (0.0, 0.0, 0.0), RADIUS_M)
    designs = candidate_designs(
        design_basis,
        [(p, plane_readout(r[:, :2].T, PAPER_PROBE.lever_m, weight)) for p, r in zip(positions, rotations)],
    )
    info = information(design_basis, [])
    now_s, decompositions, reported = 0.0, [], []
    for _ in range(SWEEPS):
        index = next_best(design_basis, info, designs, SWEEP_COVARIANCE)
        info = info + designs[index].T @ np.linalg.solve(SWEEP_COVARIANCE, designs[index])
        goal = StampedPose(0, "arm_base", positions[index], matrix_quaternion(rotations[index]))
        assert arm.move_cp(goal, now_s).accepted
        now_s += 20.0
        measured = arm.measured_cp(now_s)
        assert pose_problem(measured, int(now_s * NS_PER_S), 0.1, arm.is_busy(now_s), Reach()) == ""
        truth = arm.true_pose(now_s)
        decompositions.append(simulate_sweep(source, SweepPose(truth.position_m, truth.plane), PAPER_PROBE, rng))
        reported.append(SweepPose(measured.position_m, measured.plane))
    observations = sweep_observations(decompositions, reported, PAPER_PROBE)
    degree = choose_degree(observations, (3, 4, 5), scale_m=RADIUS_M).chosen
    basis = SolidHarmonics(degree, (0.0, 0.0, 0.0), RADIUS_M)
    model = fit_with_pose_errors(observations, basis, ACCURACY, fit(observations, basis)).model
    points = ball_points(40, RADIUS_M, rng)
    field, field_std = model.field_t(points)
    gradient, gradient_std = model.gradient_t_per_m(points)
    field_pulls = (field - source.field_t(points)) / field_std
    gradient_pulls = (gradient - source.gradient_t_per_m(points)) / gradient_std
    # 95 % of a normal within 2σ; the points share one fit's few largest errors: at least 85 %
    assert np.mean(np.abs(field_pulls) < 2) > 0.85, np.std(field_pulls)
    assert np.mean(np.abs(gradient_pulls) < 2) > 0.85, np.std(gradient_pulls)
    assert np.sqrt(np.mean((field - source.field_t(points)) ** 2)) < 1e-3 * np.sqrt(
        np.mean(source.field_t(points) ** 2)
    )
