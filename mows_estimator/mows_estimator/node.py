"""The estimator node: fits every ring-down announced by the driver and publishes the result.

Topic and service names are relative, so the graph can run in a namespace; in the root
namespace they are the names below. Subscribes ``/mows/raw`` (MagnetometerBlock, sensor-data QoS)
and ``/mows/excitation`` (ExcitationState, transient local). Publishes, per recorded ring-down,
``/mows/ringdown`` (RingdownFit, always, with a status), and when the fit is OK ``/mows/field``
(FieldEstimate) and ``/mows/magnetic_field`` (sensor_msgs/MagneticField, REP-145). Each window is
fitted jointly over the probes its announcement lists, each at its own θ0 (all of them when it
lists none, as bags recorded before the lists do), and gives one RingdownFit per probe with its
``probe_id``: the node's own probe (0) alone, or those ``probes`` names, each in frame
``<probe_frame_id>_<id>`` and counted on /diagnostics with the fits of ids it does not know.
Service ``/estimator/calibrate`` (CalibrateF00; ``/mows/estimator/calibrate``, the previous
release's name, is served too for one release) sets f00 from the next ring-downs in a known field.
The estimation itself is :class:`mows.estimate.stream.RingdownEstimator`.
"""

import time

from mows_msgs.msg import ExcitationState, FieldEstimate, MagnetometerBlock, RingdownFit
from mows_msgs.srv import CalibrateF00
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.parameter import Parameter
from rclpy.task import Future
from sensor_msgs.msg import MagneticField

from mows.estimate.probe_set import probe_frame_id
from mows.estimate.settings import FitParameters
from mows.estimate.stream import Estimated, FitSettings, RingdownEstimator
from mows.physics.probe import Probe
from mows.precompile import precompile
from mows_estimator.health import FitTally
from mows_estimator.messages import estimate_to_msg, fit_to_msg, magnetic_field_msg
from mows_estimator.parameters import PARAMETERS
from mows_ros.awaitables import within
from mows_ros.diagnostics import Health
from mows_ros.node import MowsNode
from mows_ros.params import parameter_values
from mows_ros.probe import probe_of
from mows_ros.process import run_node
from mows_ros.qos import EXCITATION_QOS, RESULT_QOS, STREAM_QOS

NODE_NAME = "estimator"
CALIBRATE_SERVICES = ("~/calibrate", "mows/estimator/calibrate")  # the node's own, the previous release's


class EstimatorNode(MowsNode):
    """One thread for everything (``mows_ros.process``): the calibration service awaits its
    ring-downs as a coroutine. (With rclpy 7.1's MultiThreadedExecutor the stream fell behind
    for whole runs at 40 blocks/s: fits published 0.2–1.5 s late, blocks lost.)"""

    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self._estimator = RingdownEstimator(self.get_parameter("buffer_s").value)
        self._tally = FitTally()
        self._calibrated = Future()
        self.create_subscription(MagnetometerBlock, "mows/raw", self.when_active(self._on_block), STREAM_QOS)
        on_excitation = self.when_active(self._on_excitation)  # transient local: heard if sent before discovery
        self.create_subscription(ExcitationState, "mows/excitation", on_excitation, EXCITATION_QOS)
        self._fit_pub = self.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
        self._field_pub = self.create_publisher(FieldEstimate, "mows/field", RESULT_QOS)
        self._magnetic_pub = self.create_publisher(MagneticField, "mows/magnetic_field", STREAM_QOS)
        # A group of its own, reentrant: an awaiting calibration holds its group until it
        # returns. In the default group it would stop the stream that brings its ring-downs; in
        # a mutually exclusive one a second request would wait instead of being refused.
        group = ReentrantCallbackGroup()
        for name in CALIBRATE_SERVICES:
            self.create_service(CalibrateF00, name, self._on_calibrate, callback_group=group)

    def configure(self) -> None:
        # Compile the fit (or load it from numba's cache) now, not on the first real ring-down.
        self.get_logger().info(f"fit kernels ready in {precompile(simulator=False):.1f} s")

    def _settings(self) -> FitSettings:
        return FitParameters.of(parameter_values(self, PARAMETERS)).fit_settings(self._probe())

    def _probe(self) -> Probe:
        return probe_of(self.get_parameter("probe_file").value)

    def _named(self) -> bool:
        """Whether ``probes`` names the probes: their fits then carry frames and counts of their own."""
        return bool(self.get_parameter("probes").value.strip())

    # --- stream -----------------------------------------------------------------------------
    def _on_excitation(self, msg: ExcitationState):
        fit_tuning = self.get_parameter("fit_tuning_ringdowns").value
        self._take(lambda m: self._estimator.announce(m, fit_tuning), msg, "malformed_excitation", "{error}: ignored")

    def _on_block(self, msg: MagnetometerBlock):
        warning = f"malformed MagnetometerBlock {msg.sequence}: {{error}}"  # not samples a device could send
        self._take(self._estimator.add_block, msg, "malformed_blocks", warning)

    def _take(self, feed, msg, malformed: str, warning: str):
        """Feed ``msg`` to the estimator and publish the ring-downs it completes."""
        arrived = time.monotonic()
        try:
            segments = feed(msg)
        except ValueError as error:
            self._tally.count(malformed)
            self.get_logger().warn(warning.format(error=error))
            return
        if segments:  # the settings (parameters, the probe file) are read only for a ring-down
            for estimated in self._estimator.estimate_segments(segments, self._settings()):
                self._publish(estimated, arrived)

    def _publish(self, estimated: Estimated, arrived: float):
        named = self._named()
        frame_id = probe_frame_id(self.get_parameter("probe_frame_id").value, estimated.probe_id, named)
        fit_msg = fit_to_msg(estimated, frame_id)
        self._fit_pub.publish(fit_msg)
        if estimated.estimate.ok:
            self._field_pub.publish(estimate_to_msg(estimated.estimate, fit_msg.header, estimated.window))
            self._magnetic_pub.publish(magnetic_field_msg(estimated.estimate, fit_msg.header))
        if estimated.calibrated:
            self._calibrated.set_result(True)
        self._tally.add(estimated, 1e3 * (time.monotonic() - arrived), named)
        if not estimated.fit.ok:
            self.get_logger().warn(estimated.report())

    # --- calibration ------------------------------------------------------------------------
    async def _on_calibrate(self, request: CalibrateF00.Request, response: CalibrateF00.Response):
        """f00 from the next ring-downs (:class:`mows.estimate.calibration.f00.F00Calibration`)."""
        try:  # one refusal path: a node not active, or a request the core refuses
            if (inactive := self.inactive_reason()) is not None:
                raise ValueError(inactive)
            calibration = self._estimator.begin_calibration(
                self._settings(), request.reference_field_t, request.n_ringdowns, request.timeout_s
            )
        except ValueError as error:
            response.success, response.message = False, str(error)
            return response
        self._calibrated = Future()
        try:
            if not await within(self, self._calibrated, request.timeout_s):
                calibration.time_up()
        finally:
            self._estimator.end_calibration()
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
        own = FitParameters.of(parameter_values(self, PARAMETERS)).own_entry(self._probe())
        return self._tally.health(self._estimator.last, self._estimator.assembler, own.f00_hz, own.f00_std_hz)


def main(args: list[str] | None = None) -> int:
    return run_node(EstimatorNode, args)
