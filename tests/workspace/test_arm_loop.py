"""The whole core path of a workspace map: a simulated CRTK arm carries the probe to poses the
map chooses (:class:`PosePlan`, D-optimal among reachable candidates), the probe sweeps where the
arm truly put it in an eight-coil field from Biot–Savart, the sweep's own decomposition reports B
and G, each sweep enters the map at the pose the arm reported (:func:`workspace_map`, which
carries the arm's stated accuracy). The map's predictions land within 2σ of the truth at
held-out points."""

import math

import numpy as np
import pytest

from mows.physics.probe import PAPER_PROBE
from mows.sim.navigation import navigation_system
from mows.workspace.arm import NS_PER_S, Reach, SimulatedArm
from mows.workspace.mapping import MapSettings, PosePlan, PoseWatch, sweep_observations, workspace_map
from mows.workspace.poses import PoseError
from mows.workspace.simulated import SweepPose, ball_points, simulate_sweep

RADIUS_M = 0.015  # a 3 cm workspace: twelve sweeps hold its field to degree 5
SWEEPS = 12
ACCURACY = PoseError(1e-4, math.radians(0.01))  # an industrial arm's


@pytest.mark.slow
def test_mapper_chosen_poses_give_a_map_within_two_sigma():
    rng = np.random.default_rng(12)
    source = navigation_system(1.5e-3, seed=2)
    arm = SimulatedArm(rng, ACCURACY, PoseError(1e-6, 1e-6), Reach(), latency_s=0.02)
    settings = MapSettings((0.0, 0.0, 0.0), RADIUS_M, ACCURACY, Reach(), degrees=(3, 4, 5))
    plan = PosePlan(settings, PAPER_PROBE)
    watch = PoseWatch(1e-4, math.radians(0.05), 0.1, settings.reach)
    now_s, sweeps = 0.0, []
    for _ in range(SWEEPS):
        goal = plan.next_goal()
        assert arm.move_cp(goal, now_s).accepted
        now_s += 20.0
        for _ in range(2):  # two reports at rest: the arm is still
            watch.on_pose(arm.measured_cp(now_s))
        assert watch.arrived(goal)
        assert watch.start_problem(int(now_s * NS_PER_S), "arm_base") == ""
        truth = arm.true_pose(now_s)
        decomposition = simulate_sweep(source, SweepPose(truth.position_m, truth.plane), PAPER_PROBE, rng)
        now_s += 15.0
        watch.on_pose(arm.measured_cp(now_s))
        assert watch.end_problem(int(now_s * NS_PER_S)) == ""
        sweeps.append((decomposition, watch.latest))
        plan.swept(sweep_observations(sweeps[-1:], PAPER_PROBE, settings)[0])
    model = workspace_map(sweeps, PAPER_PROBE, settings).model
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
