"""The driver's services and its measurement-cycle action: each request checked against the
limits of the driver's parameters, translated into a call on the device session, and its
outcome back into the response, with a log line.

A cycle is asked for through the action ``~/measurement_cycle`` (MeasurementCycle: cancellable)
or its shortcut, the service ``~/run_cycle`` (RunCycle). Both run the same coroutine, which
awaits the streaming thread (which completes the cycle) in a reentrant group, so that the
emergency stop and the parameter services are served meanwhile. A cycle ends early, coils off
at the device's next sample, when its goal is cancelled or when every node that may wait for
it has left the graph (``mows_ros.requesters``). ``set_field_current`` awaits the supply's
ramp the same way.

Names are node-private (``/driver/run_cycle`` in the root namespace); the names of the
previous release (``/mows/driver/run_cycle`` and its two siblings) are served too, as aliases,
for one release (docs/robot_integration.md).
"""

from collections.abc import Callable

from mows_msgs.action import MeasurementCycle
from mows_msgs.srv import EmergencyStop, RunCycle, SetFieldCurrent
from rclpy.action import CancelResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.task import Future

from mows.device.cycle.phases import CycleOutcome
from mows_driver.messages import (
    cycle_request,
    cycle_response,
    estop_response,
    estop_unlinked_response,
    supply_range,
    supply_response,
)
from mows_driver.parameters import cycle_request_problem, supply_problem
from mows_ros.awaitables import completer
from mows_ros.goals import action_servers
from mows_ros.requesters import RequesterWatch
from mows_ros.wall import steady_timer

RUN_CYCLE_SERVICE = "~/run_cycle"
EMERGENCY_STOP_SERVICE = "~/emergency_stop"
SET_FIELD_CURRENT_SERVICE = "~/set_field_current"
MEASUREMENT_CYCLE_ACTION = "~/measurement_cycle"
ALIASES = {  # the previous release's names, served beside the private ones for one release
    RUN_CYCLE_SERVICE: "mows/driver/run_cycle",
    EMERGENCY_STOP_SERVICE: "mows/driver/emergency_stop",
    SET_FIELD_CURRENT_SERVICE: "mows/driver/set_field_current",
}
WATCH_S = 0.1  # how often a running cycle looks for its requesters in the graph


class DriverServices:
    """The services and the action of ``node`` (a DriverNode: its ``session``, ``linked()``)."""

    def __init__(self, node):
        self._node, self._log = node, node.get_logger()
        self._group = group = ReentrantCallbackGroup()
        for name, kind, callback in (
            (RUN_CYCLE_SERVICE, RunCycle, self.run_cycle),
            (EMERGENCY_STOP_SERVICE, EmergencyStop, self.emergency_stop),
            (SET_FIELD_CURRENT_SERVICE, SetFieldCurrent, self.set_field_current),
        ):
            node.create_service(kind, name, callback, callback_group=group)
            node.create_service(kind, ALIASES[name], callback, callback_group=group)
        self._actions = action_servers(
            node, MeasurementCycle, [MEASUREMENT_CYCLE_ACTION], self._execute_cycle, self._cancel_cycle, group
        )
        self._goal_cycles: dict[bytes, int] = {}  # the cycle of each running goal, by goal id
        self._watched: dict[int, RequesterWatch] = {}  # the running cycles' requesters
        self._watch_timer = steady_timer(node, WATCH_S, self._watch, callback_group=group)

    # --- one cycle, asked for by the service or the action ------------------------------------
    async def _cycle(self, request, asked_through: str, started: Callable[[int], None]) -> CycleOutcome:
        """Run the cycle ``request`` asks for, asked through the service or action named
        ``asked_through``; ``started(cycle_id)`` once it runs. Its outcome (a refusal: failed)."""
        finished = Future()
        try:
            if (problem := cycle_request_problem(request)) is not None:
                raise ValueError(problem)
            # the streaming thread (the emergency stop, a cancel) completes it
            cycle_id = self._node.linked().start_cycle(cycle_request(request), completer(self._node, finished))
        except ValueError as refused:
            self._log.warning(f"cycle refused: {refused}")
            return CycleOutcome(False, f"cycle refused: {refused}", 0, float("nan"), 0)
        self._watched[cycle_id] = RequesterWatch(self._node, (asked_through,))
        started(cycle_id)
        try:
            outcome = await finished
        finally:
            self._watched.pop(cycle_id, None)
        # One call site per severity: rclpy refuses to change a call site's severity. A cancel
        # (its client's, a deactivate) is asked for: no error.
        if outcome.success:
            self._log.info(f"cycle {outcome.cycle_id}: {outcome.message}")
        elif outcome.cancelled:
            self._log.info(f"cycle {outcome.cycle_id} ended: {outcome.message}")
        else:
            self._log.error(f"cycle {outcome.cycle_id}: {outcome.message}")
        return outcome

    def _watch(self) -> None:
        """Cancel every running cycle whose requesters have all left the graph."""
        for cycle_id, watch in list(self._watched.items()):
            if watch.gone() and (session := self._node.session) is not None:
                if session.cancel_cycle(cycle_id, watch.reason):
                    self._log.warning(f"cycle {cycle_id} cancelled, coils off: {watch.reason}")

    async def run_cycle(self, request: RunCycle.Request, response: RunCycle.Response) -> RunCycle.Response:
        outcome = await self._cycle(request, self._node.resolve_service_name(RUN_CYCLE_SERVICE), lambda _: None)
        return cycle_response(outcome, response)

    async def _execute_cycle(self, goal_handle) -> MeasurementCycle.Result:
        goal_id = bytes(goal_handle.goal_id.uuid)

        def started(cycle_id: int) -> None:
            self._goal_cycles[goal_id] = cycle_id
            goal_handle.publish_feedback(MeasurementCycle.Feedback(cycle_id=cycle_id))

        send_goal = self._node.resolve_service_name(MEASUREMENT_CYCLE_ACTION) + "/_action/send_goal"
        try:
            outcome = await self._cycle(goal_handle.request, send_goal, started)
        finally:
            self._goal_cycles.pop(goal_id, None)
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
        elif outcome.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return cycle_response(outcome, MeasurementCycle.Result())

    def _cancel_cycle(self, goal_handle) -> CancelResponse:
        cycle_id = self._goal_cycles.get(bytes(goal_handle.goal_id.uuid))
        if cycle_id is not None and (session := self._node.session) is not None:
            session.cancel_cycle(cycle_id, "its goal was cancelled")
        return CancelResponse.ACCEPT

    # --- the supply and the emergency stop ----------------------------------------------------
    async def set_field_current(
        self, request: SetFieldCurrent.Request, response: SetFieldCurrent.Response
    ) -> SetFieldCurrent.Response:
        reached = Future()
        session = self._node.session
        supply_range(session and session.backend.supply_limits, self._node.values["supply_current_cap_a"], response)
        try:  # the streaming thread completes it once the samples have reached the ramp's end
            if (problem := supply_problem(request.current_a, self._node.values)) is not None:
                raise ValueError(problem)
            self._node.linked().set_field_current(request.current_a, completer(self._node, reached))
        except ValueError as refused:
            response.success, response.message = False, f"supply current refused: {refused}"
            response.current_a = float("nan")
            self._log.warning(response.message)
            return response
        supply_response(await reached, request.current_a, response)
        self._log.info(response.message)
        return response

    def emergency_stop(
        self, request: EmergencyStop.Request, response: EmergencyStop.Response
    ) -> EmergencyStop.Response:
        if (session := self._node.session) is None:
            return estop_unlinked_response(self._node.lifecycle_state, response)
        estop_response(session.emergency_stop(request.engage, request.reason), request, response, session.backend.name)
        if request.engage:
            self._log.warning(f"emergency stop engaged: {request.reason or 'no reason given'}")
        else:
            self._log.info("emergency stop released")
        return response
