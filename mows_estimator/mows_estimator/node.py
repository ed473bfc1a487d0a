"""The estimator node: fits every ring-down announced by the driver and publishes the result.

Topic and service names are relative, so the graph can run in a namespace; in the root
namespace they are the names below. Subscribes ``/mows/raw`` (MagnetometerBlock, sensor-data
QoS) and ``/mows/excitation`` (ExcitationState). Publishes, per recorded ring-down,
``/mows/ringdown`` (RingdownFit, always, with a status), and when the fit is OK ``/mows/field`` (FieldEstimate) and
``/mows/magnetic_field`` (sensor_msgs/MagneticField, REP-145). Service
``/mows/estimator/calibrate`` (Calibrate) sets f00 from the next ring-downs in a known field.
The estimation itself is ``mows.estimate.segments``, ``mows.estimate.ringdown`` and ``mows.estimate.axis``.
"""

import time

from mows_msgs.msg import ExcitationState, FieldEstimate, MagnetometerBlock, RingdownFit
from mows_msgs.srv import Calibrate
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.parameter import Parameter
from rclpy.task import Future
from sensor_msgs.msg import MagneticField

from mows.estimate.axis import estimate_along_axis
from mows.estimate.calibration import F00Calibration
from mows.estimate.ringdown import FitStatus, failure
from mows.estimate.segments import SegmentAssembler, block_from_message, fit_segment, window_from_message
from mows.physics.probe import Probe
from mows.precompile import precompile
from mows_estimator.health import FitTally
from mows_estimator.messages import estimate_to_msg, fit_to_msg, magnetic_field_msg
from mows_estimator.parameters import PARAMETERS, fit_options
from mows_ros.awaitables import within
from mows_ros.diagnostics import Health
from mows_ros.node import MowsNode
from mows_ros.params import parameter_values
from mows_ros.probe import probe_of
from mows_ros.process import run_node
from mows_ros.qos import RESULT_QOS, STREAM_QOS

NODE_NAME = "estimator"


class EstimatorNode(MowsNode):
    """One thread for everything (``mows_ros.process``): the calibration service awaits its
    ring-downs as a coroutine. (With rclpy 7.1's MultiThreadedExecutor the stream fell behind
    for whole runs at 40 blocks/s: fits published 0.2–1.5 s late, blocks lost.)"""

    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        # Compile the fit (or load it from numba's cache) now, not on the first real ring-down;
        # subscriptions and publishers come after, so a node that advertises results can make them.
        self.get_logger().info(f"fit kernels ready in {precompile(simulator=False):.1f} s")
        self._assembler = SegmentAssembler(self.get_parameter("buffer_s").value)
        self._tally = FitTally()
        self._last = "no ring-down yet"
        self._calibration: F00Calibration | None = None
        self._calibrated = Future()
        self.create_subscription(MagnetometerBlock, "mows/raw", self._on_block, STREAM_QOS)
        self.create_subscription(ExcitationState, "mows/excitation", self._on_excitation, RESULT_QOS)
        self._fit_pub = self.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
        self._field_pub = self.create_publisher(FieldEstimate, "mows/field", RESULT_QOS)
        self._magnetic_pub = self.create_publisher(MagneticField, "mows/magnetic_field", STREAM_QOS)
        # A group of its own, reentrant: an awaiting calibration holds its group until it
        # returns. In the default group it would stop the stream that brings its ring-downs; in
        # a mutually exclusive one a second request would wait instead of being refused.
        self.create_service(
            Calibrate, "mows/estimator/calibrate", self._on_calibrate, callback_group=ReentrantCallbackGroup()
        )

    # --- parameters -------------------------------------------------------------------------
    def _param(self, name):
        return self.get_parameter(name).value

    def probe(self) -> Probe:
        return probe_of(self._param("probe_file"))

    def f00(self) -> tuple[float, float]:
        f00 = self._param("f00_hz")
        return (f00 if f00 > 0 else self.probe().f00_hz), self._param("f00_std_hz")

    # --- stream -----------------------------------------------------------------------------
    def _on_excitation(self, msg: ExcitationState):
        if msg.phase != ExcitationState.PHASE_RINGDOWN or (msg.tuning and not self._param("fit_tuning_ringdowns")):
            return
        arrived = time.monotonic()
        try:
            window = window_from_message(msg)
        except ValueError as error:
            self._tally.count("malformed_excitation")
            self.get_logger().warn(f"{error}: ignored")
            return
        for segment in self._assembler.announce(window):
            self._process(segment, arrived)

    def _on_block(self, msg: MagnetometerBlock):
        arrived = time.monotonic()
        try:
            block = block_from_message(msg)
        except ValueError as error:  # not samples a device could have sent: nothing usable
            self._tally.count("malformed_blocks")
            self.get_logger().warn(f"malformed MagnetometerBlock {msg.sequence}: {error}")
            return
        for segment in self._assembler.add_block(block):
            self._process(segment, arrived)

    def _process(self, segment, arrived: float):
        try:
            options = fit_options(parameter_values(self, PARAMETERS), self.probe(), segment.window.theta0_rad)
        except ValueError as error:  # e.g. a sensing axis of (0, 0): no model to fit
            fit = failure(
                FitStatus.BAD_FIT, f"cannot build the signal model: {error}", theta0_rad=segment.window.theta0_rad
            )
        else:
            fit = fit_segment(segment, options, self._param("settle_s"), self.probe().damping_per_s)
        f00, f00_std = self.f00()
        estimate = estimate_along_axis(fit, self.probe(), f00, f00_std)
        frame = self._param("probe_frame_id")
        fit_msg = fit_to_msg(fit, segment.window, frame, estimate.frequency_shift_hz, estimate.frequency_shift_std_hz)
        self._fit_pub.publish(fit_msg)
        if estimate.ok:
            self._field_pub.publish(estimate_to_msg(estimate, fit_msg.header, segment.window))
            self._magnetic_pub.publish(magnetic_field_msg(estimate, fit_msg.header))
            self._offer_to_calibration(fit.frequency_hz, fit.frequency_std_hz)
        self._tally.add(fit.status.name, 1e3 * (time.monotonic() - arrived))
        self._last = fit.report()
        if not fit.ok:
            self.get_logger().warn(
                f"cycle {segment.window.cycle_id} repeat {segment.window.repeat_index}: {fit.report()}"
            )

    # --- calibration ------------------------------------------------------------------------
    def _offer_to_calibration(self, frequency_hz: float, std_hz: float):
        if self._calibration is not None and self._calibration.offer(frequency_hz, std_hz) is not None:
            self._calibrated.set_result(True)

    async def _on_calibrate(self, request: Calibrate.Request, response: Calibrate.Response):
        """f00 from the next ring-downs (:class:`mows.estimate.calibration.F00Calibration`)."""
        try:
            calibration = F00Calibration(
                self.probe(), request.reference_field_t, request.n_ringdowns, request.timeout_s
            )
        except ValueError as error:
            response.success, response.message = False, str(error)
            return response
        if self._calibration is not None:
            response.success, response.message = False, "a calibration is already running: try again after it"
            return response
        self._calibration, self._calibrated = calibration, Future()
        try:
            if not await within(self, self._calibrated, request.timeout_s):
                calibration.time_up()
        finally:
            self._calibration = None
        outcome = calibration.outcome
        response.n_used, response.success, response.message = outcome.n_used, outcome.ok, outcome.message
        if outcome.ok:
            response.f00_hz, response.f00_std_hz = outcome.f00_hz, outcome.f00_std_hz
            # Out-of-range values (an f00 uncertainty above 10 Hz says the ring-downs were not of
            # one probe in one field) are refused by the parameters' ranges, with the reason.
            result = self.set_parameters_atomically(
                [
                    Parameter("f00_hz", Parameter.Type.DOUBLE, outcome.f00_hz),
                    Parameter("f00_std_hz", Parameter.Type.DOUBLE, outcome.f00_std_hz),
                ]
            )
            response.success, response.message = result.successful, result.reason or outcome.message
        return response

    # --- health ---------------------------------------------------------------------------
    def health(self) -> Health:
        return self._tally.health(self._last, self._assembler, *self.f00())


def main(args: list[str] | None = None) -> int:
    return run_node(EstimatorNode, args)
