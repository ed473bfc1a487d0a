"""A node's way to the driver's measurement cycles, shared by the mapper and the calibrator:
RunCycle calls answered as the core's :class:`mows.sweep.runner.CycleAnswer`, and the ring-down
fits of ``/mows/ringdown`` handed to the node, whose answer to each (the core's next step, or
None) resumes the coroutine that waits for a cycle's fits."""

from collections.abc import Callable

from mows_msgs.msg import RingdownFit
from mows_msgs.srv import RunCycle
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node

from mows.sweep.runner import CycleAnswer
from mows_ros.awaitables import Delivery, call
from mows_ros.qos import RESULT_QOS


def run_cycle_request(action) -> RunCycle.Request:
    """A cycle of ``action.repeats`` ring-downs at ``action.theta0_rad``; tuning steps and gap
    are the driver's parameters (−1)."""
    return RunCycle.Request(
        theta0_rad=float(action.theta0_rad), repeats=int(action.repeats), tuning_steps=-1, gap_s=-1.0
    )


def cycle_answer(response: RunCycle.Response | None) -> CycleAnswer:
    """A RunCycle response (None: none came); ``problem`` is the driver's reason when it ran none."""
    if response is None:
        return CycleAnswer(problem="no answer from the driver")
    if not response.success:
        return CycleAnswer(problem=response.message or "the driver ran no cycle (no reason given)")
    return CycleAnswer(response.cycle_id, response.ringdowns_recorded)


class DriverCycles:
    """``node``'s RunCycle client and ``/mows/ringdown`` subscription; every fit goes to
    ``on_fit``. Both are in ``group``, reentrant, which the node's action server shares: a goal
    that awaits its cycle holds its group, and the fits and the driver's answer must still come."""

    def __init__(self, node: Node, on_fit: Callable[[RingdownFit], object]):
        self._node = node
        self._fits_in = Delivery(node)
        self.group = group = ReentrantCallbackGroup()
        self._client = node.create_client(RunCycle, "mows/driver/run_cycle", callback_group=group)
        deliver = self._fits_in.deliver
        node.create_subscription(
            RingdownFit, "mows/ringdown", lambda msg: deliver(on_fit(msg)), RESULT_QOS, callback_group=group
        )

    def ready(self) -> bool:
        """Whether the driver's run_cycle service is there."""
        return self._client.service_is_ready()

    async def run(self, action, timeout_s: float) -> CycleAnswer:
        """The driver's answer to a cycle of ``action`` (waiting up to ``timeout_s`` for the
        service to appear and again for its answer)."""
        return cycle_answer(await call(self._node, self._client, run_cycle_request(action), timeout_s))

    async def fits(self, timeout_s: float, time_up: Callable[[], object]):
        """The first non-None answer of ``on_fit`` from now, or ``time_up()``'s after ``timeout_s``."""
        return await self._fits_in.wait(timeout_s, time_up)
