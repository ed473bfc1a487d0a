"""The mapper's checks on the arm's reported poses (:class:`PoseWatch`): a pose that is stale,
outside the reach, in another frame, or of an arm still moving is refused with the reason, and
so is a sweep during which the arm moved; the pose plan stays within the reach."""

import math

import numpy as np
import pytest

from mows.physics.probe import PAPER_PROBE
from mows.workspace.arm import NS_PER_S, Reach, StampedPose
from mows.workspace.mapping import MapSettings, PosePlan, PoseWatch, WorkspaceMap, turned, workspace_map
from mows.workspace.poses import PoseError

REACH = Reach((0.0, 0.0, 0.0), 0.1, 0.6)
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def pose(time_s, position=(0.3, 0.0, 0.0), frame="arm_base", quaternion=IDENTITY):
    return StampedPose(int(time_s * NS_PER_S), frame, np.array(position), np.asarray(quaternion))


def watch():
    return PoseWatch(1e-4, math.radians(0.05), 0.5, REACH)


def test_a_still_fresh_pose_within_reach_stands_for_a_sweep():
    w = watch()
    w.on_pose(pose(1.0))
    w.on_pose(pose(1.02, (0.30001, 0.0, 0.0)))
    assert w.arrived(pose(0.0)) and w.start_problem(int(1.1 * NS_PER_S), "arm_base") == ""
    w.on_pose(pose(5.0, (0.30002, 0.0, 0.0)))
    assert w.end_problem(int(5.1 * NS_PER_S)) == ""


@pytest.mark.parametrize(
    ("reports", "now_s", "reason"),
    [
        ([pose(1.0), pose(1.02)], 2.0, "stale pose: 0.980 s old"),
        ([pose(1.0), pose(1.02, (0.301, 0.0, 0.0))], 1.05, "the arm is moving"),
        ([pose(1.0, (0.7, 0, 0)), pose(1.02, (0.7, 0, 0))], 1.05, "outside the arm's reach: 700.0 mm"),
        ([pose(1.0, frame="world"), pose(1.02, frame="world")], 1.05, "frame 'world', the map is in 'arm_base'"),
        ([], 1.05, "no pose from the arm's measured_cp"),
    ],
)
def test_a_pose_that_cannot_stand_for_a_sweep_is_refused_with_the_reason(reports, now_s, reason):
    w = watch()
    for report in reports:
        w.on_pose(report)
    assert reason in w.start_problem(int(now_s * NS_PER_S), "arm_base")


def test_a_sweep_during_which_the_arm_moved_or_fell_silent_is_refused():
    w = watch()
    w.on_pose(pose(1.0))
    w.on_pose(pose(1.02))
    assert w.start_problem(int(1.05 * NS_PER_S), "arm_base") == ""
    w.on_pose(pose(3.0, (0.3, 0.0005, 0.0)))
    w.on_pose(pose(5.0))
    assert "moved during the sweep's ring-downs: 0.500 mm" in w.end_problem(int(5.05 * NS_PER_S))
    w.on_pose(pose(5.02))
    assert w.start_problem(int(5.05 * NS_PER_S), "arm_base") == ""
    assert "stale pose at the sweep's end: 2.980 s old" in w.end_problem(int(8.0 * NS_PER_S))


def test_the_plan_asks_only_for_poses_within_reach_and_says_when_none_is_left():
    # the reach cuts the workspace's sphere: a shell that holds only its near half
    settings = MapSettings((0.3, 0.0, 0.0), 0.02, PoseError(1e-4, 1e-4), Reach((0.0, 0.0, 0.0), 0.1, 0.3))
    plan = PosePlan(settings, PAPER_PROBE)
    goals = []
    with pytest.raises(ValueError, match="no pose left within the arm's reach"):
        while True:
            goals.append(plan.next_goal())
    assert 0 < len(goals) < 240
    assert all(g.frame_id == "arm_base" and np.linalg.norm(g.position_m) <= 0.3 for g in goals)


def test_a_map_refuses_sweeps_in_another_frame():
    settings = MapSettings((0.3, 0.0, 0.0), 0.02, PoseError(1e-4, 1e-4), REACH)
    with pytest.raises(ValueError, match="frame 'world', the map is in 'arm_base'"):
        workspace_map([(None, pose(1.0, frame="world"))], PAPER_PROBE, settings)


def test_a_map_does_not_extrapolate_beyond_its_workspace():
    settings = MapSettings((0.3, 0.0, 0.0), 0.02, PoseError(1e-4, 1e-4), REACH)
    the_map = WorkspaceMap(None, None, (), settings)
    assert the_map.outside_problem(np.array([0.3, 0.0, 0.019])) == ""
    assert "25.0 mm from the workspace's centre, outside its 20.0 mm" in the_map.outside_problem([0.3, 0.025, 0.0])
    assert "outside" in the_map.outside_problem([math.nan, 0.0, 0.0])


def test_an_arm_that_turns_the_probe_may_turn_about_the_normal_but_not_tilt_it():
    w = PoseWatch(1e-4, math.radians(0.05), 0.5, REACH, turns_probe=True)
    w.on_pose(pose(1.0))
    w.on_pose(pose(1.02))
    assert w.start_problem(int(1.05 * NS_PER_S), "arm_base") == ""
    for k, theta in enumerate(np.radians([45.0, 90.0, 315.0])):
        w.on_pose(turned(pose(2.0 + k), theta))
    assert turned(pose(0.0), math.pi / 2).rotation @ [1, 0, 0] == pytest.approx([0, 1, 0])
    w.on_pose(pose(5.0))
    assert w.end_problem(int(5.05 * NS_PER_S)) == ""
    tilted = (math.sin(math.radians(0.05)), 0.0, 0.0, math.cos(math.radians(0.05)))  # 0.1° about x
    w.on_pose(pose(5.5, quaternion=tilted))
    assert "0.100° from where it started" in w.end_problem(int(5.55 * NS_PER_S))
