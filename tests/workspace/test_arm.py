"""The simulated CRTK arm: moves take time and end off the goal by its accuracy, its
measured_cp arrives late and noisy, goals out of reach or sent while busy are refused with the
reason, and the mapper's check refuses stale poses and a moving probe."""

import math

import numpy as np

from mows.workspace.arm import (
    NS_PER_S,
    Reach,
    SimulatedArm,
    StampedPose,
    matrix_quaternion,
    pose_problem,
    quaternion_matrix,
)
from mows.workspace.poses import PoseError, rotation

REACH = Reach()
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


SURGICAL = PoseError(1e-3, math.radians(1.0))
ENCODERS = PoseError(1e-5, 1e-5)


def arm(seed=0):
    return SimulatedArm(np.random.default_rng(seed), SURGICAL, ENCODERS, REACH, latency_s=0.02)


def goal(position, quaternion=IDENTITY, frame="arm_base"):
    return StampedPose(0, frame, np.asarray(position, float), np.asarray(quaternion, float))


def test_quaternions_and_matrices_agree():
    turn = rotation(np.array([0.4, -0.3, 1.1]))
    assert np.allclose(quaternion_matrix(matrix_quaternion(turn)), turn)


def test_goals_out_of_reach_in_another_frame_or_while_busy_are_refused_with_the_reason():
    a = arm()
    assert "outside the arm's reach" in a.move_cp(goal([0.0, 0.0, 0.3]), 0.0).reason
    assert "inside the arm's reach" in a.move_cp(goal([0.0, 0.0, -0.25]), 0.0).reason
    assert "frame" in a.move_cp(goal([0.0, 0.0, 0.0], frame="world"), 0.0).reason
    assert a.move_cp(goal([0.0, 0.0, 0.1]), 0.0).accepted
    assert a.is_busy(1.0)  # 0.1 m at 0.05 m/s: 2 s
    assert "busy" in a.move_cp(goal([0.01, 0.0, 0.0]), 1.0).reason
    assert not a.is_busy(2.1) and a.move_cp(goal([0.01, 0.0, 0.0]), 2.1).accepted


def test_measured_cp_is_late_noisy_and_not_where_the_tool_is():
    offsets, angles = [], []
    a = arm(seed=3)
    now = 0.0
    for k in range(300):
        target = goal([0.01 * math.cos(k), 0.01 * math.sin(k), 0.0])
        assert a.move_cp(target, now).accepted
        now += 10.0
        measured, truth = a.measured_cp(now), a.true_pose(now)
        assert (
            measured.stamp_ns == int(round((now - 0.02) * NS_PER_S))
            or abs(measured.stamp_ns - (now - 0.02) * NS_PER_S) < 2
        )
        offsets.append(truth.position_m - measured.position_m)
        relative = truth.rotation @ measured.rotation.T
        angles.append(math.acos(np.clip((np.trace(relative) - 1) / 2, -1, 1)))
    # 900 components of N(0, 1 mm): the sd is known to 2.4 %
    assert 0.92e-3 < np.std(offsets) < 1.08e-3
    # the angle of a rotation vector of three N(0, 1°) components: rms √3·1°
    assert 0.92 * math.sqrt(3) < math.degrees(np.sqrt(np.mean(np.square(angles)))) < 1.08 * math.sqrt(3)


def test_the_mapper_refuses_a_stale_pose_and_a_moving_probe():
    a = arm()
    a.move_cp(goal([0.0, 0.0, 0.0]), 0.0)
    pose = a.measured_cp(10.0)
    assert pose_problem(pose, int(10.0 * NS_PER_S), 0.1, False, REACH) == ""
    assert "stale" in pose_problem(pose, int(10.5 * NS_PER_S), 0.1, False, REACH)
    assert "moving" in pose_problem(pose, int(10.0 * NS_PER_S), 0.1, True, REACH)
    far = StampedPose(pose.stamp_ns, "arm_base", np.array([0.0, 0.0, 0.5]), IDENTITY)
    assert "reach" in pose_problem(far, int(10.0 * NS_PER_S), 0.1, False, REACH)


def test_measured_cp_follows_a_move_so_the_mapper_sees_the_arm_moving():
    a = arm()
    assert a.move_cp(goal([0.0, 0.0, 0.1]), 0.0).accepted  # 2 s at 0.05 m/s
    halfway = a.measured_cp(1.02)  # where it was 20 ms earlier: halfway
    np.testing.assert_allclose(halfway.position_m, [0.0, 0.0, 0.05], atol=1e-4)
    arrived = a.measured_cp(3.0)
    np.testing.assert_allclose(arrived.position_m, [0.0, 0.0, 0.1], atol=1e-4)
    half_turn = matrix_quaternion(rotation(np.array([0.0, 0.0, math.pi / 2])))
    assert a.move_cp(goal([0.0, 0.0, 0.1], half_turn), 3.0).accepted  # π/2 at 1 rad/s
    turning = a.measured_cp(3.0 + math.pi / 4 + 0.02)
    np.testing.assert_allclose(turning.rotation, rotation(np.array([0.0, 0.0, math.pi / 4])), atol=1e-4)


def test_a_turn_of_the_last_joint_keeps_the_arms_error_a_move_draws_a_new_one():
    a = arm()
    start = goal([0.0, 0.0, 0.1])
    assert a.move_cp(start, 0.0).accepted
    before = a.true_pose(10.0)
    quarter = matrix_quaternion(quaternion_matrix(IDENTITY) @ rotation(np.array([0.0, 0.0, math.pi / 2])))
    assert a.move_cp(goal([0.0, 0.0, 0.1], quarter), 10.0).accepted
    after = a.true_pose(20.0)
    np.testing.assert_allclose(after.position_m, before.position_m, atol=1e-15)
    np.testing.assert_allclose(after.rotation[:, 2], before.rotation[:, 2], atol=1e-12)
    assert a.move_cp(goal([0.0, 0.0, 0.12]), 20.0).accepted
    moved = a.true_pose(30.0)
    assert abs(np.linalg.norm(moved.position_m - before.position_m) - 0.02) > 1e-5  # a fresh error
