"""The driver node: ROS side of the device (the simulator, a serial device, a recorded bag).

It translates only: the device, the stream and the cycle are
:class:`mows.device.session.DeviceSession`; parameters in ``parameters.py``. A streaming
thread steps the session and publishes what it yields, blocks on ``mows/raw`` and phases on
``mows/excitation``, in order, writing them to the bag first when recording. Everything else
runs on one executor thread: ``run_cycle`` awaits its cycle as a coroutine (in a reentrant
group), so the emergency stop, the parameter services and the diagnostics are served while it
waits. Topic and service names are relative: in the root namespace they are /mows/raw,
/mows/excitation, /mows/driver/run_cycle, /mows/driver/emergency_stop and
/mows/driver/set_field_current (docs/driver.md); the supply's ramps go out (and are recorded) on /mows/supply.

A managed node (``mows_ros.node``): ``configure`` checks the parameters and opens the device
link (and the bag) and reads the device from then on; ``activate`` publishes the stream and
arms the session, the only state in which a coil may be energised; ``deactivate`` switches the
coils off at the device's next sample, fails a running cycle, ramps the supply to zero, stops
publishing the stream (``mows/excitation`` still says what the coils do) and refuses cycles
with the reason; ``cleanup`` closes the link. The rule is the core's
(:class:`mows.device.session.DeviceSession` refuses to energise unless armed).

The node never dies on data and never publishes a number it did not measure: what goes
wrong is in the service responses, on /diagnostics and in the log. The coils are off in
every phase but EXCITING, in every lifecycle state but active, and when the node stops (SIGINT,
SIGTERM), and the static-field supply is ramped to zero when it stops.
"""

import threading
import time
import traceback

from mows_msgs.msg import ExcitationState, MagnetometerBlock, SupplyState
from mows_msgs.srv import EmergencyStop, RunCycle, SetFieldCurrent
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.task import Future
from sensor_msgs.msg import JointState

from mows.device.phases import Phase
from mows.device.session import DeviceSession
from mows.physics.coils import CurrentCap
from mows.precompile import precompile
from mows_driver.health import StreamHealth
from mows_driver.messages import (
    block_msg,
    cycle_request,
    cycle_response,
    estop_response,
    excitation_msg,
    joint_state_msg,
    supply_msg,
    supply_response,
)
from mows_driver.parameters import (
    PARAMETERS,
    current_problem,
    cycle_settings,
    make_backend,
    session_config,
    settings_problem,
    supply_problem,
    tracking_changed,
    tracking_settings,
)
from mows_driver.recording import open_recorder
from mows_ros.awaitables import completer
from mows_ros.diagnostics import Health
from mows_ros.node import MowsNode
from mows_ros.params import parameter_values
from mows_ros.process import run_node
from mows_ros.qos import EXCITATION_QOS, JOINT_QOS, STREAM_QOS

NODE_NAME = "driver"
RAW_TOPIC = "mows/raw"
EXCITATION_TOPIC = "mows/excitation"
SUPPLY_TOPIC = "mows/supply"
JOINT_STATES_TOPIC = "mows/joint_states"
RUN_CYCLE_SERVICE = "mows/driver/run_cycle"
EMERGENCY_STOP_SERVICE = "mows/driver/emergency_stop"
SET_FIELD_CURRENT_SERVICE = "mows/driver/set_field_current"
POLL_S = 0.02  # the streaming thread's longest wait for the device
INACTIVE = "the driver is not active (lifecycle): coils off, no cycles, no supply current"


class DriverNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self._values = parameter_values(self, PARAMETERS)
        self.session: DeviceSession | None = None  # from configure to cleanup: the device link
        self.recorder = None
        self.blocks_published = 0
        self.stream_errors = 0
        self._health = StreamHealth()
        self.raw_publisher = self.create_publisher(MagnetometerBlock, RAW_TOPIC, STREAM_QOS)
        self.excitation_publisher = self.create_publisher(ExcitationState, EXCITATION_TOPIC, EXCITATION_QOS)
        self.supply_publisher = self.create_publisher(SupplyState, SUPPLY_TOPIC, EXCITATION_QOS)
        self.joint_publisher = self.create_publisher(JointState, JOINT_STATES_TOPIC, JOINT_QOS)
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        group = ReentrantCallbackGroup()
        self.create_service(RunCycle, RUN_CYCLE_SERVICE, self._run_cycle, callback_group=group)
        self.create_service(EmergencyStop, EMERGENCY_STOP_SERVICE, self._emergency_stop, callback_group=group)
        self.create_service(SetFieldCurrent, SET_FIELD_CURRENT_SERVICE, self._set_field_current, callback_group=group)
        self._stopping = threading.Event()
        self._streaming: threading.Thread | None = None

    # --- the lifecycle ---------------------------------------------------------------------
    def configure(self) -> None:
        """Check the parameters together, open the device link and the bag, and stream from the
        device (published only while active), disarmed."""
        values = self._values
        if (problem := current_problem(values)) is not None:
            raise ValueError(problem)
        cap = CurrentCap(values["coil_current_cap_a"])
        # The cycle fits its tuning ring-downs and the sim backend integrates: compile both (or
        # load them from numba's cache) now, not while the device streams.
        self.get_logger().info(f"numba kernels ready in {precompile(simulator=values['backend'] == 'sim'):.1f} s")
        backend = make_backend(values, cap)  # a ValueError or OSError refuses, with its reason
        try:
            self.recorder = open_recorder(
                values["record_path"],
                [
                    (self.raw_publisher, STREAM_QOS),
                    (self.excitation_publisher, EXCITATION_QOS),
                    (self.supply_publisher, EXCITATION_QOS),
                ],
            )
        except BaseException:
            backend.close()
            raise
        self.session = DeviceSession(backend, session_config(values, cap))
        self.session.disarm(INACTIVE)
        if values["backend"] == "sim":  # the simulated stage starts where the parameter puts it
            self.session.stage_angle_rad = values["theta0_rad"]
        self.session.set_tracking(tracking_settings(values))  # a ValueError refuses, with its reason
        self._stopping.clear()
        self._streaming = threading.Thread(target=self._stream, name="mows-driver-stream", daemon=True)
        self._streaming.start()

    def activate(self) -> None:
        assert self.session is not None  # activate comes after configure
        self.session.arm()

    def deactivate(self) -> None:
        """Coils off at the device's next sample, a running cycle failed, the supply ramped to
        zero; the stream is no longer published."""
        assert self.session is not None  # deactivate comes after activate
        self.session.disarm(INACTIVE)

    def cleanup(self) -> None:
        """Stop streaming, coils off, supply to zero, device released, bag closed."""
        self._stopping.set()
        if self._streaming is not None and self._streaming.is_alive():
            self._streaming.join()
        self._streaming = None
        if self.session is not None:
            self.session.close()
            self.session = None
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None

    # --- parameters ------------------------------------------------------------------------
    def _validate(self, parameters) -> SetParametersResult:
        """Checks across parameters (each one alone is checked by its table row)."""
        reason = settings_problem({**self._values, **{p.name: p.value for p in parameters}})
        return SetParametersResult(successful=reason is None, reason=reason or "")

    def _apply(self, parameters) -> None:
        self._values = {**self._values, **{p.name: p.value for p in parameters}}
        if self.session is not None:  # else configure reads them
            self.session.set_block_duration(self._values["block_duration_s"])
            self.session.set_cycle_settings(cycle_settings(self._values))
            if tracking_changed(p.name for p in parameters):  # an emergency stop's end of tracking holds till then
                self.session.set_tracking(tracking_settings(self._values))

    # --- services --------------------------------------------------------------------------
    async def _run_cycle(self, request: RunCycle.Request, response: RunCycle.Response) -> RunCycle.Response:
        finished = Future()
        try:  # the streaming thread (or the emergency stop) completes it
            response.cycle_id = self._linked().start_cycle(cycle_request(request), completer(self, finished))
        except ValueError as refused:
            response.success, response.message = False, f"cycle refused: {refused}"
            self.get_logger().warning(response.message)
            return response
        outcome = await finished
        cycle_response(outcome, response)
        # One call site per severity: rclpy refuses to change a call site's severity.
        if outcome.success:
            self.get_logger().info(f"cycle {outcome.cycle_id}: {outcome.message}")
        else:
            self.get_logger().error(f"cycle {outcome.cycle_id}: {outcome.message}")
        return response

    async def _set_field_current(
        self, request: SetFieldCurrent.Request, response: SetFieldCurrent.Response
    ) -> SetFieldCurrent.Response:
        reached = Future()
        try:  # the streaming thread completes it once the samples have reached the ramp's end
            if (problem := supply_problem(request.current_a, self._values)) is not None:
                raise ValueError(problem)
            self._linked().set_field_current(request.current_a, completer(self, reached))
        except ValueError as refused:
            response.success, response.message = False, f"supply current refused: {refused}"
            self.get_logger().warning(response.message)
            return response
        supply_response(await reached, request.current_a, response)
        self.get_logger().info(response.message)
        return response

    def _emergency_stop(
        self, request: EmergencyStop.Request, response: EmergencyStop.Response
    ) -> EmergencyStop.Response:
        if self.session is None:
            response.success, response.latched = False, False
            response.message = f"the driver is {self.lifecycle_state}: no device link, nothing it drives is on"
            return response
        estop_response(
            self.session.emergency_stop(request.engage, request.reason), request, response, self.session.backend.name
        )
        if request.engage:
            self.get_logger().warning(f"emergency stop engaged: {request.reason or 'no reason given'}")
        else:
            self.get_logger().info("emergency stop released")
        return response

    def _linked(self) -> DeviceSession:
        """The device session; ValueError, with the reason, while there is none."""
        if self.session is None:
            raise ValueError(f"the driver is {self.lifecycle_state}: no device link")
        return self.session

    # --- streaming -------------------------------------------------------------------------
    def _stream(self) -> None:
        """From configure to cleanup: the device is read (a live one keeps streaming whatever we
        do), and what it sends is published while the driver is active. A recording replays
        once, so it waits for an active driver with its subscribers."""
        session = self._linked()
        replay = session.backend.name == "bag"
        wanted = self._values["bag_wait_subscribers"] if replay else 0

        def ready() -> bool:
            return not replay or (self.active and self.raw_publisher.get_subscription_count() >= wanted)

        while not ready() and not self._stopping.wait(POLL_S):
            pass
        while not self._stopping.is_set():
            try:
                self._publish_step(session.step(POLL_S))
            except Exception:  # a bug must not stop the stream; it is logged and counted
                if not self.context.ok():
                    return
                self.stream_errors += 1
                self.get_logger().error(f"streaming step failed:\n{traceback.format_exc()}")
                time.sleep(POLL_S)

    def _publish_step(self, output) -> None:
        for link in output.links:  # in every state, not only in a cycle
            (self.get_logger().info if link.up else self.get_logger().warning)(
                f"link {'up' if link.up else 'lost'}: {link.reason}"
            )
        # Published only while armed (active): disarming flips it under the session's lock, so
        # no block with a sample read after the deactivation is published.
        for block in output.blocks if self._linked().armed else ():
            self._publish(
                self.raw_publisher,
                block_msg(block, self.session.backend.info, self._values["frame_id"], self._values["sensor_frame_ids"]),
            )
            self.blocks_published += 1
            if self.session.stage_angle_rad is not None:  # the stage with every block: TF at its stamps
                self.joint_publisher.publish(joint_state_msg(block.stamp_ns, self.session.stage_angle_rad))
        for event in output.events:
            self._publish(self.excitation_publisher, excitation_msg(event, self._values["probe_frame_id"]))
            if event.phase == Phase.FAULT:
                self.get_logger().error(f"coils forced off: {event.reason}")
        for supply in output.supply:
            self._publish(self.supply_publisher, supply_msg(supply, self._values["probe_frame_id"]))

    def _publish(self, publisher, message) -> None:
        """Record (first: a subscriber never has a message the bag lacks), then publish."""
        if self.recorder is not None:
            self.recorder.write(publisher.topic_name, message, time.time_ns())
        publisher.publish(message)

    # --- health and shutdown ---------------------------------------------------------------
    def health(self) -> Health:
        if self.session is None:
            return super().health()
        recorded = self.recorder.messages if self.recorder else 0
        counts = {"blocks_published": self.blocks_published, "recorded_messages": recorded}
        return self._health.report(self.session, super().health().values, self.stream_errors, counts)


def main(args: list[str] | None = None) -> int:
    return run_node(DriverNode, args)
