"""A node's way to the driver's measurement cycles, shared by the mapper and the calibrator:
the core's :class:`mows.device.cycle.phases.CycleRequest` as a goal of the driver's MeasurementCycle
action, answered as the core's :class:`mows.sweep.events.CycleAnswer`; a running cycle
cancelled when the caller gives up on it; a cycle whose acceptance was lost awaited by its
goal's id; and the ring-down fits of ``/mows/ringdown`` handed
to the node, whose answer to each (the core's next step, or None) resumes the coroutine that
waits for a cycle's fits."""

import uuid
from collections.abc import Callable

from action_msgs.msg import GoalStatus
from mows_msgs.action import MeasurementCycle
from mows_msgs.msg import RingdownFit
from rclpy.action import ActionClient
from rclpy.action.client import ClientGoalHandle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from unique_identifier_msgs.msg import UUID

from mows.device.cycle.phases import CycleRequest
from mows.sweep.events import CycleAnswer
from mows_ros.awaitables import Delivery, until, within
from mows_ros.qos import RESULT_QOS

CYCLE_ACTION = "driver/measurement_cycle"  # the driver's, in the caller's namespace
GOAL_ANSWER_S = 10.0  # longest wait for the driver to accept a goal (it answers in milliseconds)
FITS_HEARD_S = 10.0  # longest wait, before a cycle, for discovery to match a publisher of the fits
CANCELLED_BEFORE = "cancelled before the cycle was asked for"


def cycle_goal(request: CycleRequest) -> MeasurementCycle.Goal:
    """A cycle of ``request.repeats`` ring-downs at ``request.theta0_rad`` (turned by hand when the
    request says so); tuning steps, gap and repeats the request leaves open (None) are the
    driver's parameters (−1)."""
    repeats = -1 if request.repeats is None else int(request.repeats)
    return MeasurementCycle.Goal(
        theta0_rad=float(request.theta0_rad),
        repeats=repeats,
        tuning_steps=-1,
        gap_s=-1.0,
        turned_by_hand=request.turned_by_hand,
    )


def cycle_answer(result: MeasurementCycle.Result) -> CycleAnswer:
    """A MeasurementCycle result; ``problem`` is the driver's reason when the cycle failed."""
    if not result.success:
        return CycleAnswer(problem=result.message or "the driver ran no cycle (no reason given)")
    return CycleAnswer(result.cycle_id, result.ringdowns_recorded)


class DriverCycles:
    """``node``'s MeasurementCycle client and ``/mows/ringdown`` subscription; every fit goes to
    ``on_fit``. Both are in ``group``, reentrant, which the node's action server shares: a goal
    that awaits its cycle holds its group, and the fits and the driver's answer must still come."""

    def __init__(self, node: Node, on_fit: Callable[[RingdownFit], object]):
        self._node = node
        self._fits_in = Delivery(node)
        self.group = group = ReentrantCallbackGroup()
        self._client = ActionClient(node, MeasurementCycle, CYCLE_ACTION, callback_group=group)
        self._running = None  # the goal handle of the cycle awaited now
        deliver = self._fits_in.deliver
        self._fit_subscription = node.create_subscription(
            RingdownFit, "mows/ringdown", lambda msg: deliver(on_fit(msg)), RESULT_QOS, callback_group=group
        )

    def ready(self) -> bool:
        """Whether the driver's measurement-cycle action is there."""
        return self._client.server_is_ready()

    def hears_fits(self) -> bool:
        """Whether discovery has matched a publisher of the fits (an estimator) to this node."""
        return self._fit_subscription.get_publisher_count() > 0

    async def run(
        self, request: CycleRequest, timeout_s: float, cancelled: Callable[[], bool] = lambda: False
    ) -> CycleAnswer:
        """The driver's answer to ``request``: waiting up to ``timeout_s`` for the
        action to appear and again for the cycle, which is cancelled when it takes longer. A
        cancel of the caller's (``cancelled()``) that came before the goal was sent sends none;
        one that came while it was being sent cancels it once the driver has it."""
        if not await until(self._node, self.ready, timeout_s):
            return CycleAnswer(problem=f"the driver's {CYCLE_ACTION} action did not appear within {timeout_s:g} s")
        # Fits are volatile: those published before discovery matches this node are never heard,
        # and a loaded machine takes seconds. Without an estimator the cycle still runs; the
        # caller's wait for its fits then reports them missing.
        await until(self._node, lambda: self.hears_fits() or cancelled(), FITS_HEARD_S)
        if cancelled():
            return CycleAnswer(problem=CANCELLED_BEFORE)
        goal_id = UUID(uuid=list(uuid.uuid4().bytes))
        sent = self._client.send_goal_async(cycle_goal(request), goal_uuid=goal_id)
        if await within(self._node, sent, GOAL_ANSWER_S):
            handle = sent.result()
            if not handle.accepted:
                return CycleAnswer(problem="the driver rejected the cycle goal")
        else:
            # The driver's answer was lost (over a lossy link DDS drops a response whose reader
            # it has not matched yet) while it may be running the cycle: its result is asked
            # for by the goal's id, and a goal the driver never received comes back unknown.
            accepted = MeasurementCycle.Impl.SendGoalService.Response(accepted=True)
            handle = ClientGoalHandle(self._client, goal_id, accepted)
        self._running = handle
        if cancelled():  # cancel() came while the goal was on its way: nothing to cancel then
            handle.cancel_goal_async()
        try:
            result = handle.get_result_async()
            if not await within(self._node, result, timeout_s):
                handle.cancel_goal_async()
                return CycleAnswer(problem=f"the cycle took longer than cycle_timeout_s = {timeout_s:g} s: cancelled")
            if result.result().status == GoalStatus.STATUS_UNKNOWN:
                return CycleAnswer(problem=f"the driver did not answer the cycle goal within {GOAL_ANSWER_S:g} s")
            return cycle_answer(result.result().result)
        finally:
            self._running = None

    def cancel(self) -> None:
        """Cancel the cycle awaited now, if any (its answer then says it was cancelled)."""
        if self._running is not None:
            self._running.cancel_goal_async()

    def deliver(self, step) -> None:
        """Resume the coroutine awaiting :meth:`fits` with ``step`` (None: nothing), as a fit would."""
        self._fits_in.deliver(step)

    async def fits(self, timeout_s: float, time_up: Callable[[], object]):
        """The first non-None answer of ``on_fit`` from now, or ``time_up()``'s after ``timeout_s``."""
        return await self._fits_in.wait(timeout_s, time_up)
