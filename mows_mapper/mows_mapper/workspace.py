"""The mapper's workspace map: the probe on an arm that speaks CRTK, a sweep at each pose the
map asks for, and the model of B and G over the workspace (docs/workspace_maps.md).

Action ``~/workspace_map`` (WorkspaceMap) runs :class:`mows.workspace.runner.MapRunner`: each
pose it asks for goes to the arm on ``<arm>/move_cp``, the arm's ``<arm>/measured_cp`` (both
geometry_msgs/PoseStamped) is fed to it and waited on, each sweep it asks for runs through the
node, and its feedback (each pose visited, accepted or refused with the reason) goes to the
goal. The fitted map goes on ``mows/workspace_model`` (transient local) and answers
``~/field_at`` (FieldAt). This module translates only.
"""

import functools
import math
from collections.abc import Awaitable, Callable

from geometry_msgs.msg import PoseStamped
from mows_msgs.action import WorkspaceMap
from mows_msgs.msg import WorkspaceModel
from mows_msgs.srv import FieldAt
from rclpy.node import Node

from mows.physics.probe import Probe
from mows.sweep.events import SweepGoal, SweepOutcome
from mows.workspace.arm import Reach, StampedPose
from mows.workspace.mapping import MapSettings, PoseWatch
from mows.workspace.mapping import WorkspaceMap as FittedMap
from mows.workspace.poses import PoseError
from mows.workspace.runner import MapRunner, MapStep
from mows_mapper.workspace_messages import feedback_msg, field_at_response, pose_stamped_msg, workspace_model_msg
from mows_ros.awaitables import in_worker, until
from mows_ros.qos import MAP_QOS, STREAM_QOS

ACTION = "~/workspace_map"
Turn = Callable[[float], Awaitable[str]]  # the arm turns the probe to θ0: '' or why it did not
Sweep = Callable[[SweepGoal, Turn | None], Awaitable[SweepOutcome]]  # one rotation sweep where the probe is


def map_settings(values: dict, goal: WorkspaceMap.Goal) -> MapSettings:
    """The goal's workspace (the parameters' where it leaves them out); ValueError for one
    that is not a workspace."""
    centre = tuple(goal.centre_m) if len(goal.centre_m) else tuple(values[f"workspace_{a}_m"] for a in "xyz")
    if len(centre) != 3:
        raise ValueError(f"a workspace's centre is 3 numbers (x, y, z) in metres, got {list(centre)}")
    # the reach about the arm's base, the origin of its frame
    reach = Reach((0.0, 0.0, 0.0), values["reach_min_radius_m"], values["reach_max_radius_m"])
    accuracy = PoseError(values["arm_position_std_m"], math.radians(values["arm_angle_std_deg"]))
    radius = goal.radius_m or values["workspace_radius_m"]
    return MapSettings(centre, radius, accuracy, reach, values["arm_frame"])


class ArmMapping:
    """The workspace map's topics, service and the run of one goal on ``node``; ``values()``
    reads the node's parameters, ``sweep`` runs one rotation sweep where the probe is."""

    def __init__(self, node: Node, values: Callable[[], dict], sweep: Sweep):
        self._node, self._values, self._sweep = node, values, sweep
        self.watch = self._pose_watch(Reach())
        arm = values()["arm"]
        node.create_subscription(PoseStamped, f"{arm}/measured_cp", self._on_pose, STREAM_QOS)
        self._move = node.create_publisher(PoseStamped, f"{arm}/move_cp", 10)
        self._models = node.create_publisher(WorkspaceModel, "mows/workspace_model", MAP_QOS)
        self.latest: FittedMap | None = None
        node.create_service(FieldAt, "~/field_at", lambda req, res: field_at_response(self.latest, req, res))
        self.bad_poses = 0

    def _pose_watch(self, reach: Reach) -> PoseWatch:
        values = self._values()
        tolerance_rad = math.radians(values["arm_tolerance_deg"])
        turns = values["turn_with"] == "arm"
        return PoseWatch(values["arm_tolerance_m"], tolerance_rad, values["pose_max_age_s"], reach, turns)

    def _on_pose(self, msg: PoseStamped) -> None:
        try:
            pose = StampedPose.of(msg)
        except ValueError as error:  # a malformed pose never stands for a sweep
            self.bad_poses += 1
            self._node.get_logger().warning(f"measured_cp ignored: {error}", throttle_duration_sec=5.0)
            return
        self.watch.on_pose(pose)

    def _now_ns(self) -> int:
        return self._node.get_clock().now().nanoseconds

    async def run(self, goal_handle, probe: Probe, cancelled: Callable[[], bool]) -> WorkspaceMap.Result:
        """The runner's map of the goal: its steps carried out until it ends, the map published."""
        goal, values = goal_handle.request, self._values()
        settings = map_settings(values, goal)
        count = goal.sweeps or values["workspace_sweeps"]
        sweep_goal = SweepGoal.asked(goal.theta0_rad, goal.repeats_per_angle)
        self.watch = self._pose_watch(settings.reach)
        runner = MapRunner(settings, probe, self.watch, count, sweep_goal)
        step = runner.begin()
        while True:
            if step.feedback is not None:
                goal_handle.publish_feedback(feedback_msg(step.feedback))
            if step.warning:
                self._node.get_logger().warning(step.warning)
            if step.finished is not None:
                break
            step = await self._advance(runner, step, cancelled)
        end = step.finished
        if end.map is None:
            return WorkspaceMap.Result(success=False, message=end.message)
        self.latest = end.map
        msg = workspace_model_msg(end.map, list(end.sweep_ids), end.stamp_ns)
        self._models.publish(msg)
        self._node.get_logger().info(end.message)
        return WorkspaceMap.Result(success=True, message=end.message, model=msg)

    async def _advance(self, runner: MapRunner, step: MapStep, cancelled: Callable[[], bool]) -> MapStep:
        """``step``'s move, sweep or fit carried out: the runner's next step (a cancel that came
        meanwhile fed first)."""
        if step.move is not None:
            timeout_s = self._values()["move_timeout_s"]
            arrived = await self._reach(runner, step.move, timeout_s)
            if cancelled():
                runner.cancel()
            return runner.on_arrived(self._now_ns()) if arrived else runner.move_timed_out(timeout_s)
        if step.sweep is not None:
            outcome = await self._sweep(step.sweep, functools.partial(self._turn, runner) if step.turns else None)
            if cancelled():
                runner.cancel()
            return runner.on_swept(outcome, self._now_ns())
        return runner.on_fitted(await in_worker(self._node, step.fit))

    async def _reach(self, runner: MapRunner, target: StampedPose, timeout_s: float) -> bool:
        """Ask the arm for ``target``: whether it reports being there within ``timeout_s``."""
        self._move.publish(pose_stamped_msg(target))
        return await until(self._node, runner.arrived, timeout_s)

    async def _turn(self, runner: MapRunner, theta0_rad: float) -> str:
        """The arm's last joint turns the probe to ``theta0_rad``: '' or why it did not."""
        timeout_s = self._values()["move_timeout_s"]
        if await self._reach(runner, runner.turn(theta0_rad), timeout_s):
            return ""
        return runner.turn_timed_out(timeout_s)
