"""The mapper's workspace map: the probe on an arm that speaks CRTK, a sweep at each pose the
map asks for, and the model of B and G over the workspace (docs/workspace_maps.md).

Action ``~/workspace_map`` (WorkspaceMap): for each sweep the next pose from
:class:`mows.workspace.mapping.PosePlan` goes to the arm on ``<arm>/move_cp``; once the arm's
``<arm>/measured_cp`` (both geometry_msgs/PoseStamped) reports it there and still, that report
is the sweep's pose, checked (:class:`mows.workspace.mapping.PoseWatch`: frame, age, reach,
stillness) before the sweep and again after it (the probe must not have moved during its
ring-downs). A refused pose is reported in the feedback with the reason and the plan moves on
to the next. The fitted map goes on ``mows/workspace_model`` (transient local) and answers
``~/field_at`` (FieldAt).
"""

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
from mows.workspace.mapping import MapSettings, PosePlan, PoseWatch, sweep_observations, turned, workspace_map
from mows.workspace.mapping import WorkspaceMap as FittedMap
from mows.workspace.poses import PoseError
from mows_mapper.messages import outcome_decomposition_msg
from mows_mapper.workspace_messages import field_at_response, pose_stamped_msg, workspace_model_msg
from mows_ros.awaitables import in_worker, until
from mows_ros.qos import MAP_QOS, STREAM_QOS

ACTION = "~/workspace_map"
# A map gives up after this many poses in a row are refused: an arm that never gets there
REFUSALS_IN_A_ROW = 5
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
            self.watch.on_pose(StampedPose.of(msg))
        except ValueError as error:  # a malformed pose never stands for a sweep
            self.bad_poses += 1
            self._node.get_logger().warning(f"measured_cp ignored: {error}", throttle_duration_sec=5.0)

    def _now_ns(self) -> int:
        return self._node.get_clock().now().nanoseconds

    async def run(self, goal_handle, probe: Probe, cancelled: Callable[[], bool]) -> WorkspaceMap.Result:
        """Sweep at the poses the plan chooses until the goal's count is in, then fit and publish."""
        goal, values = goal_handle.request, self._values()
        settings = map_settings(values, goal)
        self.watch = self._pose_watch(settings.reach)
        plan, count = PosePlan(settings, probe), goal.sweeps or values["workspace_sweeps"]
        sweeps, sweep_ids, stamp_ns, refused, refusal = [], [], 0, 0, ""
        sweep_goal = SweepGoal.asked(goal.theta0_rad, goal.repeats_per_angle)
        while len(sweeps) < count and not cancelled():
            if refused >= REFUSALS_IN_A_ROW:
                return WorkspaceMap.Result(
                    success=False, message=f"{refused} poses in a row refused, the last: {refusal}"
                )
            refusal, outcome = await self._visit(plan.next_goal(), settings, sweep_goal, cancelled)
            if cancelled():  # the pose and its sweep given up, not refused
                break
            pose = self.watch.latest if refusal else self.watch.start
            feedback = WorkspaceMap.Feedback(
                sweep_index=len(sweeps), n_sweeps=count, accepted=not refusal, refusal=refusal
            )
            if pose is not None:
                feedback.pose = pose_stamped_msg(pose)
            if outcome is not None and outcome.map is not None:
                feedback.decomposition = outcome_decomposition_msg(outcome, "", False)
            goal_handle.publish_feedback(feedback)
            if outcome is not None and not outcome.ok and not cancelled():  # not the pose: the sweep itself
                return WorkspaceMap.Result(success=False, message=f"workspace map failed: {outcome.message}")
            if refusal:
                self._node.get_logger().warning(f"pose refused: {refusal}")
                refused += 1
                continue
            refused = 0
            plan.swept(sweep_observations([(outcome.map.decomposition, pose)], probe, settings)[0])
            sweeps.append((outcome.map.decomposition, pose))
            sweep_ids.append(outcome.map.sweep_id)
            stamp_ns = max(stamp_ns, max((p.stamp_ns for p in outcome.map.record.points), default=0))
        if cancelled():
            return WorkspaceMap.Result(success=False, message="workspace map cancelled")
        the_map = await in_worker(self._node, workspace_map, sweeps, probe, settings)
        self.latest = the_map
        msg = workspace_model_msg(the_map, sweep_ids, stamp_ns)
        self._models.publish(msg)
        message = (
            f"workspace map of {len(sweeps)} sweeps: {the_map.choice.report()}; rms σ over the workspace "
            f"{msg.field_error_t * 1e6:.3f} µT, {msg.gradient_error_t_per_m * 1e6:.1f} µT/m"
        )
        self._node.get_logger().info(message)
        return WorkspaceMap.Result(success=True, message=message, model=msg)

    async def _reach(self, target, what: str) -> str:
        """Ask the arm for ``target`` and wait for its report there: '' or why it did not."""
        timeout_s = self._values()["move_timeout_s"]
        self._move.publish(pose_stamped_msg(target))
        if not await until(self._node, lambda: self.watch.arrived(target), timeout_s):
            return f"the arm did not {what} within {timeout_s:.0f} s"
        return ""

    def _turns_from(self, pose) -> Turn:
        """The arm's last joint turning the probe about the normal of ``pose``'s plane."""

        async def turn(theta0_rad: float) -> str:
            return await self._reach(turned(pose, theta0_rad), f"turn the probe to θ0 = {math.degrees(theta0_rad):g}°")

        return turn

    async def _visit(
        self, target, settings: MapSettings, sweep_goal: SweepGoal, cancelled: Callable[[], bool]
    ) -> tuple[str, SweepOutcome | None]:
        """Move to ``target``, check the pose, sweep unless the map was cancelled on the way,
        check again: the refusal ('' for none) and the sweep's outcome."""
        if problem := await self._reach(target, "report the pose asked for"):
            return problem, None
        if problem := self.watch.start_problem(self._now_ns(), settings.frame_id):
            return problem, None
        if cancelled():
            return "", None
        outcome = await self._sweep(sweep_goal, self._turns_from(target) if self.watch.turns_probe else None)
        if not outcome.ok:
            return outcome.message, outcome
        return self.watch.end_problem(self._now_ns()), outcome
