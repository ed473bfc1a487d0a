"""The driver's services: each request translated into a call on the device session, and
its outcome back into the response, with a log line.

``run_cycle`` and ``set_field_current`` are coroutines that await the streaming thread (which
completes the cycle, or the ramp once the device's samples have reached its end), in a reentrant
group, so that the emergency stop and the parameter services are served while they wait. Names
are relative: /mows/driver/run_cycle, /mows/driver/emergency_stop and
/mows/driver/set_field_current in the root namespace (docs/driver.md).
"""

from mows_msgs.srv import EmergencyStop, RunCycle, SetFieldCurrent
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.task import Future

from mows_driver.messages import (
    cycle_request,
    cycle_response,
    estop_response,
    estop_unlinked_response,
    supply_response,
)
from mows_driver.parameters import supply_problem
from mows_ros.awaitables import completer

RUN_CYCLE_SERVICE = "mows/driver/run_cycle"
EMERGENCY_STOP_SERVICE = "mows/driver/emergency_stop"
SET_FIELD_CURRENT_SERVICE = "mows/driver/set_field_current"


class DriverServices:
    """The services of ``node`` (a DriverNode: its ``session``, ``linked()``, ``values``)."""

    def __init__(self, node):
        self._node, self._log = node, node.get_logger()
        group = ReentrantCallbackGroup()
        node.create_service(RunCycle, RUN_CYCLE_SERVICE, self.run_cycle, callback_group=group)
        node.create_service(EmergencyStop, EMERGENCY_STOP_SERVICE, self.emergency_stop, callback_group=group)
        node.create_service(SetFieldCurrent, SET_FIELD_CURRENT_SERVICE, self.set_field_current, callback_group=group)

    async def run_cycle(self, request: RunCycle.Request, response: RunCycle.Response) -> RunCycle.Response:
        finished = Future()
        try:  # the streaming thread (or the emergency stop) completes it
            response.cycle_id = self._node.linked().start_cycle(cycle_request(request), completer(self._node, finished))
        except ValueError as refused:
            response.success, response.message = False, f"cycle refused: {refused}"
            self._log.warning(response.message)
            return response
        outcome = await finished
        cycle_response(outcome, response)
        # One call site per severity: rclpy refuses to change a call site's severity.
        if outcome.success:
            self._log.info(f"cycle {outcome.cycle_id}: {outcome.message}")
        else:
            self._log.error(f"cycle {outcome.cycle_id}: {outcome.message}")
        return response

    async def set_field_current(
        self, request: SetFieldCurrent.Request, response: SetFieldCurrent.Response
    ) -> SetFieldCurrent.Response:
        reached = Future()
        try:  # the streaming thread completes it once the samples have reached the ramp's end
            if (problem := supply_problem(request.current_a, self._node.values)) is not None:
                raise ValueError(problem)
            self._node.linked().set_field_current(request.current_a, completer(self._node, reached))
        except ValueError as refused:
            response.success, response.message = False, f"supply current refused: {refused}"
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
