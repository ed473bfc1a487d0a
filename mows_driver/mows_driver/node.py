"""The driver node: ROS side of the device (the simulator, a serial device, a recorded bag).

It translates only: the device, the sample stream and the measurement cycle live in
``mows.device`` and ``mows.device.cycle`` (:class:`mows.device.session.DeviceSession`). A streaming
thread steps the session and publishes what it yields, blocks on ``mows/raw`` and phases on
``mows/excitation``, in order, writing them to the bag first when recording. Everything else
runs on one executor thread: ``run_cycle`` awaits its cycle as a coroutine (in a reentrant
group), so the emergency stop, the parameter services and the diagnostics are served while it
waits. Topic and service names are relative: in the root namespace they are /mows/raw,
/mows/excitation, /mows/driver/run_cycle and /mows/driver/emergency_stop (docs/driver.md).

The node never dies on data and never publishes a number it did not measure: what goes
wrong is in the service responses, on /diagnostics and in the log. The coils are off in
every phase but EXCITING and when the node stops (SIGINT, SIGTERM).
"""
import array
import math
import threading
import time
import traceback

from diagnostic_msgs.msg import DiagnosticStatus
from mows_msgs.msg import ExcitationState, MagnetometerBlock, MagnetometerChannel
from mows_msgs.srv import EmergencyStop, RunCycle
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.exceptions import InvalidParameterValueException
from rclpy.task import Future

from mows.device.backends import BagBackend, SerialBackend, SimBackend
from mows.device.phases import CycleRequest, CycleSettings, Phase
from mows.device.serial_link import DEFAULT_BAUD, SerialLink
from mows.device.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_ringdown
from mows.physics.coils import PRESETS, CurrentCap
from mows.physics.probe import PAPER_PROBE
from mows.precompile import precompile
from mows.records import stamps
from mows.sim.scenario import DEFAULT_SCENARIO, load_scenario
from mows.sim.simulator import SimulatedDevice
from mows_driver.recording import BagRecorder
from mows_ros.diagnostics import Health
from mows_ros.node import MowsNode
from mows_ros.params import ParamSpec, parameter_values
from mows_ros.process import run_node
from mows_ros.qos import EXCITATION_QOS, STREAM_QOS

NODE_NAME = "driver"
RAW_TOPIC = "mows/raw"
EXCITATION_TOPIC = "mows/excitation"
RUN_CYCLE_SERVICE = "mows/driver/run_cycle"
EMERGENCY_STOP_SERVICE = "mows/driver/emergency_stop"
POLL_S = 0.02          # the streaming thread's longest wait for the device
RATE_TOLERANCE = 0.02  # /diagnostics warns when the achieved sample rate is further off nominal

PARAMETERS = (
    ParamSpec("backend", "sim", "where magnetometer blocks come from: sim (the simulator), serial (the device on "
              "a serial port), bag (a recorded rosbag2 MCAP bag); fixed at start-up",
              choices=("sim", "serial", "bag"), read_only=True),
    ParamSpec("scenario", DEFAULT_SCENARIO, "backend sim: simulator scenario, a YAML file or the name of one "
              "shipped in mows/sim/scenarios; fixed at start-up", read_only=True),
    ParamSpec("theta0_rad", 0.0, "backend sim: probe orientation at start-up, rad (cycles turn it)",
              range=(-2.0 * math.pi, 2.0 * math.pi), read_only=True),
    ParamSpec("serial_port", "", "backend serial: the device's port, e.g. /dev/ttyACM0; fixed at start-up",
              read_only=True),
    ParamSpec("baud", DEFAULT_BAUD, "backend serial: baud rate (ignored by USB CDC links), bit/s",
              range=(9600, 12_000_000), read_only=True),
    ParamSpec("bag_path", "", "backend bag: the bag directory to replay; fixed at start-up", read_only=True),
    ParamSpec("bag_rate", 1.0, "backend bag: replay speed, multiple of real time", range=(0.01, 100.0),
              read_only=True),
    ParamSpec("bag_wait_subscribers", 0, "backend bag: start the replay once /mows/raw has this many "
              "subscribers", range=(0, 100), read_only=True),
    ParamSpec("record_path", "", "write /mows/raw and /mows/excitation to a new rosbag2 MCAP bag here "
              "('' records nothing); fixed at start-up", read_only=True),
    ParamSpec("block_duration_s", 0.025, "length of one MagnetometerBlock on /mows/raw, s", range=(0.01, 0.05)),
    ParamSpec("frame_id", "mows_magnetometer", "header.frame_id of the blocks: the magnetometer array"),
    ParamSpec("sensor_frame_ids", ["fluxgate_near", "fluxgate_far"],
              "frame of each channel (sensing axis = its x axis), near sensor first"),
    ParamSpec("probe_frame_id", "mows_probe", "header.frame_id of the excitation states: the probe"),
    ParamSpec("coil_current_cap_a", 10.0, "hard limit on the peak current of any excitation coil, A; commands "
              "above it are refused; fixed at start-up", range=(0.01, 100.0), read_only=True),
    ParamSpec("coil_setup", "largest_spacing", "excitation coil setup whose orientation-dependent current scheme "
              "drives the coils; fixed at start-up", choices=tuple(PRESETS), read_only=True),
    ParamSpec("excitation_current_a", 2.0, "base amplitude of the coil current scheme, A (at most "
              "coil_current_cap_a)", range=(0.0, 100.0)),
    ParamSpec("initial_frequency_hz", round(float(PAPER_PROBE.f00_hz), 1), "first resonance estimate, Hz (each cycle "
              "retunes it)", range=(1.0, 2000.0), read_only=True),
    ParamSpec("excite_s", 0.5, "coil-on time of one excitation, s", range=(0.01, 10.0)),
    ParamSpec("ringdown_s", 0.5, "recorded free ring-down after each excitation, s", range=(0.05, 10.0)),
    ParamSpec("gap_s", 1.0, "pause between a ring-down and the next excitation, s", range=(0.0, 600.0)),
    ParamSpec("repeats", 3, "recorded ring-downs per cycle", range=(1, 1000)),
    ParamSpec("tuning_steps", 2, "frequency-tuning excitations before the recorded ones", range=(0, 10)),
    ParamSpec("settle_s", 0.5, "wait after turning the probe, s", range=(0.0, 60.0)),
    ParamSpec("max_duty_cycle", 0.5, "largest share of any duty_window_s with the coils on", range=(0.01, 1.0)),
    ParamSpec("duty_window_s", 10.0, "window of the duty-cycle limit, s", range=(1.0, 3600.0)),
)
CYCLE_PARAMETERS = ("excitation_current_a", "excite_s", "ringdown_s", "gap_s", "repeats", "tuning_steps",
                    "settle_s", "max_duty_cycle", "duty_window_s")


def cycle_settings(values: dict) -> CycleSettings:
    return CycleSettings(**{name: values[name] for name in CYCLE_PARAMETERS})


def current_problem(values: dict) -> str | None:
    """Why the excitation current is refused (it is above the cap), or None."""
    if values["excitation_current_a"] <= values["coil_current_cap_a"]:
        return None
    return (f"excitation_current_a={values['excitation_current_a']!r} exceeds "
            f"coil_current_cap_a={values['coil_current_cap_a']!r}")


def make_backend(values: dict, cap: CurrentCap):
    """The backend the parameters choose. ValueError (naming the parameter) when it cannot be made."""
    backend = values["backend"]
    if backend == "sim":
        scenario = load_scenario(values["scenario"])
        if scenario.setup.name != values["coil_setup"]:
            raise ValueError(f"coil_setup={values['coil_setup']!r} does not drive the coils of scenario "
                             f"{values['scenario']!r} ({scenario.setup.name})")
        scenario = scenario.replace(pose=scenario.pose.with_theta0(values["theta0_rad"]))
        # Simulated in pieces of one block: blocks come out evenly, at the least cost per sample.
        return SimBackend(SimulatedDevice(scenario), cap, chunk_s=values["block_duration_s"])
    if backend == "serial":
        if not values["serial_port"]:
            raise ValueError("serial_port='' : backend serial needs the device's port")
        return SerialBackend(SerialLink(values["serial_port"], values["baud"]).start(), cap)
    if not values["bag_path"]:
        raise ValueError("bag_path='' : backend bag needs the bag to replay")
    return BagBackend(values["bag_path"], values["bag_rate"])


class DriverNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        values = parameter_values(self, PARAMETERS)
        self._values = values
        if (problem := current_problem(values)) is not None:
            raise InvalidParameterValueException("excitation_current_a", values["excitation_current_a"], problem)
        cap = CurrentCap(values["coil_current_cap_a"])
        setup = PRESETS[values["coil_setup"]](current_limit_a=cap.limit_a)
        # The cycle fits its tuning ring-downs and the sim backend integrates: compile both (or
        # load them from numba's cache) now, not while the device streams.
        self.get_logger().info(f"numba kernels ready in {precompile(simulator=values['backend'] == 'sim'):.1f} s")
        self.raw_publisher = self.create_publisher(MagnetometerBlock, RAW_TOPIC, STREAM_QOS)
        self.excitation_publisher = self.create_publisher(ExcitationState, EXCITATION_TOPIC, EXCITATION_QOS)
        try:
            backend = make_backend(values, cap)
            self.recorder = self._recorder(values["record_path"])
        except (ValueError, OSError) as error:
            raise InvalidParameterValueException("backend", values["backend"], str(error)) from None
        self.session = DeviceSession(backend, SessionConfig(values["block_duration_s"], cycle_settings(values),
                                                            setup, cap, values["initial_frequency_hz"],
                                                            fit_ringdown))
        self.blocks_published = 0
        self.stream_errors = 0
        self._reported_gaps = 0
        self._reported_faults = 0
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._apply)
        group = ReentrantCallbackGroup()
        self.create_service(RunCycle, RUN_CYCLE_SERVICE, self._run_cycle, callback_group=group)
        self.create_service(EmergencyStop, EMERGENCY_STOP_SERVICE, self._emergency_stop, callback_group=group)
        self._stopping = threading.Event()
        self._streaming = threading.Thread(target=self._stream, name="mows-driver-stream", daemon=True)
        self._streaming.start()

    def _recorder(self, path: str) -> BagRecorder | None:
        if not path:
            return None
        return BagRecorder(path, {
            self.raw_publisher.topic_name: ("mows_msgs/msg/MagnetometerBlock", STREAM_QOS),
            self.excitation_publisher.topic_name: ("mows_msgs/msg/ExcitationState", EXCITATION_QOS)})

    # --- parameters ------------------------------------------------------------------------
    def _validate(self, parameters) -> SetParametersResult:
        """Checks across parameters (each one alone is checked by its table row)."""
        changed = {**self._values, **{p.name: p.value for p in parameters}}
        reason = current_problem(changed)
        if reason is None:
            try:
                cycle_settings(changed)
            except ValueError as error:
                reason = str(error)
        return SetParametersResult(successful=reason is None, reason=reason or "")

    def _apply(self, parameters) -> None:
        self._values = {**self._values, **{p.name: p.value for p in parameters}}
        self.session.set_block_duration(self._values["block_duration_s"])
        self.session.set_cycle_settings(cycle_settings(self._values))

    # --- services --------------------------------------------------------------------------
    async def _run_cycle(self, request: RunCycle.Request, response: RunCycle.Response) -> RunCycle.Response:
        cycle = CycleRequest(request.theta0_rad, request.repeats if request.repeats >= 0 else None,
                             request.tuning_steps if request.tuning_steps >= 0 else None,
                             request.gap_s if request.gap_s >= 0.0 else None)
        finished = Future()
        executor = self.executor

        def done(outcome) -> None:  # called by the streaming thread (or the emergency stop)
            finished.set_result(outcome)
            if self.context.ok():  # at shutdown the session aborts the cycle, with no one waiting
                executor.wake()    # the awaiting coroutine resumes at the executor's next turn

        try:
            response.cycle_id = self.session.start_cycle(cycle, done)
        except ValueError as refused:
            response.success, response.message = False, f"cycle refused: {refused}"
            self.get_logger().warning(response.message)
            return response
        outcome = await finished
        response.success, response.message = outcome.success, outcome.message
        response.excitation_frequency_hz = outcome.frequency_hz
        response.ringdowns_recorded = outcome.ringdowns_recorded
        # One call site per severity: rclpy refuses to change a call site's severity.
        if outcome.success:
            self.get_logger().info(f"cycle {outcome.cycle_id}: {outcome.message}")
        else:
            self.get_logger().error(f"cycle {outcome.cycle_id}: {outcome.message}")
        return response

    def _emergency_stop(self, request: EmergencyStop.Request,
                        response: EmergencyStop.Response) -> EmergencyStop.Response:
        response.latched = self.session.emergency_stop(request.engage, request.reason)
        response.success = response.latched == request.engage
        response.message = ("coils off, latched" if response.latched else "released") if response.success \
            else f"the {self.session.backend.name} backend has no coils to stop"
        if request.engage:
            self.get_logger().warning(f"emergency stop engaged: {request.reason or 'no reason given'}")
        else:
            self.get_logger().info("emergency stop released")
        return response

    # --- streaming -------------------------------------------------------------------------
    def _stream(self) -> None:
        wanted = self._values["bag_wait_subscribers"] if self.session.backend.name == "bag" else 0
        while self.raw_publisher.get_subscription_count() < wanted and not self._stopping.wait(POLL_S):
            pass
        while not self._stopping.is_set():
            try:
                output = self.session.step(POLL_S)
                for block in output.blocks:
                    self._publish(self.raw_publisher, self._block_message(block))
                    self.blocks_published += 1
                for event in output.events:
                    self._publish(self.excitation_publisher, self._excitation_message(event))
                    if event.phase == Phase.FAULT:
                        self.get_logger().error(f"coils forced off: {event.reason}")
            except Exception:  # a bug must not stop the stream; it is logged and counted
                if not self.context.ok():
                    return
                self.stream_errors += 1
                self.get_logger().error(f"streaming step failed:\n{traceback.format_exc()}")
                time.sleep(POLL_S)

    def _publish(self, publisher, message) -> None:
        """Record (first: a subscriber never has a message the bag lacks), then publish."""
        if self.recorder is not None:
            self.recorder.write(publisher.topic_name, message, time.time_ns())
        publisher.publish(message)

    def _block_message(self, block) -> MagnetometerBlock:
        info = self.session.backend.info
        message = MagnetometerBlock(sequence=block.sequence, first_sample_index=block.first_sample_index,
                                    sample_rate_hz=info.sample_rate_hz, range_t=info.range_t,
                                    resolution_t=info.resolution_t)
        stamps.set_nanoseconds(message.header.stamp, block.stamp_ns)
        message.header.frame_id = self._values["frame_id"]
        names = self._values["sensor_frame_ids"]
        message.channels = [
            MagnetometerChannel(frame_id=names[i] if i < len(names) else f"channel_{i + 1}",
                                field_t=array.array("d", block.samples_t[:, i].tobytes()),
                                saturated=block.saturated[:, i].tolist())
            for i in range(block.samples_t.shape[1])]
        return message

    def _excitation_message(self, event) -> ExcitationState:
        message = ExcitationState(phase=int(event.phase), phase_name=event.phase.name, cycle_id=event.cycle_id,
                                  repeat_index=event.repeat_index, repeats=event.repeats, tuning=event.tuning,
                                  coils_on=event.coils_on, coil_current_amplitude_a=list(event.currents_a),
                                  frequency_hz=event.frequency_hz, theta0_rad=event.theta0_rad,
                                  planned_duration_s=event.planned_duration_s, setup=event.setup)
        stamps.set_nanoseconds(message.header.stamp, event.stamp_ns)
        message.header.frame_id = self._values["probe_frame_id"]
        return message

    # --- health and shutdown ---------------------------------------------------------------
    def health(self) -> Health:
        state = self.session.health()
        nominal = self.session.backend.info.sample_rate_hz if self.session.backend.info else None
        achieved = self.session.achieved_rate_hz()
        values = {**super().health().values, **state, "nominal_sample_rate_hz": nominal,
                  "achieved_sample_rate_hz": achieved, "blocks_published": self.blocks_published,
                  "stream_errors": self.stream_errors,
                  "recorded_messages": self.recorder.messages if self.recorder else 0}
        new_gaps, self._reported_gaps = state.get("gaps", 0) - self._reported_gaps, state.get("gaps", 0)
        new_faults, self._reported_faults = state["device_faults"] - self._reported_faults, state["device_faults"]
        if state["link"] == "finished":
            return Health(DiagnosticStatus.OK, "replay finished", values)
        if not state["link_up"]:
            return Health(DiagnosticStatus.ERROR, f"no device: {state['link_reason'] or state.get('last_error')}",
                          values)
        problems = []
        if state.get("estop_latched"):
            problems.append(f"emergency stop latched ({state['estop_reason']})")
        if new_faults:
            problems.append(f"device fault: {state['last_device_fault']}")
        if new_gaps:
            problems.append(f"{new_gaps} new gaps in the sample stream ({state['missing_samples']} samples "
                            "missing in all)")
        if achieved is not None and nominal and abs(achieved / nominal - 1.0) > RATE_TOLERANCE:
            problems.append(f"sample rate {achieved:.0f} Hz, nominal {nominal:.0f} Hz")
        if self.stream_errors:
            problems.append(f"{self.stream_errors} streaming errors (see the log)")
        if problems:
            return Health(DiagnosticStatus.WARN, "; ".join(problems), values)
        return Health(DiagnosticStatus.OK, f"streaming ({self.session.backend.name}), phase {state.get('phase')}",
                      values)

    def destroy_node(self) -> None:
        """Stop streaming, coils off, close the bag: on SIGINT, SIGTERM and any other exit."""
        self._stopping.set()
        if self._streaming.is_alive():
            self._streaming.join()
        self.session.close()
        if self.recorder is not None:
            self.recorder.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> int:
    return run_node(DriverNode, args)
