"""The estimator node: fits every ring-down announced by the driver and publishes the result.

Topic and service names are relative, so the graph can run in a namespace; in the root
namespace they are the names below. Subscribes ``/mows/raw`` (MagnetometerBlock, sensor-data QoS)
and ``/mows/excitation`` (ExcitationState). Publishes, per recorded ring-down, ``/mows/ringdown`` (RingdownFit, always,
with a status), and when the fit is OK ``/mows/field`` (FieldEstimate) and
``/mows/magnetic_field`` (sensor_msgs/MagneticField, REP-145). Service
``/mows/estimator/calibrate`` (Calibrate) sets f00 from the next ring-downs in a known field.
The estimation itself is ``mows.estimate.segments``, ``mows.estimate.ringdown`` and ``mows.estimate.axis``.
"""
import collections
import dataclasses
import math
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from mows_msgs.msg import ExcitationState, FieldEstimate, MagnetometerBlock, RingdownFit
from mows_msgs.srv import Calibrate
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.parameter import Parameter
from rclpy.task import Future
from sensor_msgs.msg import MagneticField

from mows.estimate.axis import estimate_along_axis
from mows.estimate.ringdown import SETTLE_S, FitOptions, FitStatus, failure
from mows.estimate.segments import SegmentAssembler, block_from_message, fit_segment, window_from_message
from mows.physics.fluxgate import PAPER_DISTANCE_M, PAPER_SPACING_M, FluxgatePair
from mows.physics.probe import Probe
from mows.precompile import precompile
from mows_estimator.messages import estimate_to_msg, fit_to_msg, magnetic_field_msg
from mows_ros.diagnostics import Health
from mows_ros.node import MowsNode
from mows_ros.params import ParamSpec
from mows_ros.probe import PROBE_FILE, probe_of
from mows_ros.process import run_node
from mows_ros.qos import RESULT_QOS, STREAM_QOS

NODE_NAME = "estimator"
LATENCY_WINDOW = 500

PARAMETERS = (
    PROBE_FILE,
    ParamSpec("f00_hz", 0.0, "calibrated zero-field frequency f00, Hz; 0: the probe file's f00",
              range=(0.0, 10_000.0)),
    ParamSpec("f00_std_hz", 0.0, "standard uncertainty of f00, Hz", range=(0.0, 10.0)),
    ParamSpec("channels", "difference", "what to fit: the sensor difference, both, or one channel",
              choices=("difference", "both", "channel1", "channel2")),
    ParamSpec("sensor_axis_a", 0.0, "sensing axis (a, b) in the rotation plane, Eq. S11 (paper: 0, 1)",
              range=(-1.0, 1.0)),
    ParamSpec("sensor_axis_b", 1.0, "see sensor_axis_a", range=(-1.0, 1.0)),
    ParamSpec("theta0_free", False, "fit θ0 instead of taking the commanded orientation (paper's signal model only)"),
    ParamSpec("lever_aware", True, "fit the exact pickup of the magnet swinging on its lever "
              "(mows.physics.fluxgate.pickup_harmonics) instead of Eq. S11's magnet turning in place"),
    ParamSpec("sensor_distance_m", PAPER_DISTANCE_M, "distance from the probe to the near fluxgate, along the "
              "rotation plane's x axis, m", range=(0.005, 2.0)),
    ParamSpec("sensor_spacing_m", PAPER_SPACING_M, "spacing of the two fluxgates, m", range=(0.001, 2.0)),
    ParamSpec("settle_s", SETTLE_S, "samples right after coil-off that are skipped, s", range=(0.0, 0.1)),
    ParamSpec("min_periods", 10.0, "shortest usable ring-down, in periods", range=(2.0, 1000.0)),
    ParamSpec("max_chi2_dof", 25.0, "above this χ²/dof a fit is refused (BAD_FIT)", range=(1.0, 1e6)),
    ParamSpec("buffer_s", 5.0, "seconds of raw samples kept to assemble ring-downs", range=(0.5, 60.0),
              read_only=True),
    ParamSpec("fit_tuning_ringdowns", False, "also fit the driver's frequency-tuning ring-downs"),
    ParamSpec("probe_frame_id", "mows_probe", "frame of the probe (x' along the moment at rest)"),
)


@dataclasses.dataclass
class _Calibration:
    """The OK ring-downs collected for one Calibrate request; ``finished`` completes when
    ``wanted`` of them are in (True) or the request's time is up (False)."""

    wanted: int
    fits: list = dataclasses.field(default_factory=list)
    finished: Future = dataclasses.field(default_factory=Future)

    def time_up(self):
        if not self.finished.done():
            self.finished.set_result(False)


class EstimatorNode(MowsNode):
    """One thread for everything (a SingleThreadedExecutor): the calibration service awaits its
    ring-downs as a coroutine instead of blocking a thread. rclpy 7.1's MultiThreadedExecutor
    re-submits a callback that has been handed to its pool but not yet started, without
    waiting, and so holds the GIL from the very thread that should run it: at 40 blocks/s the
    stream then fell behind for whole runs (fits published 0.2–1.5 s late, blocks lost)."""

    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self._warm_up()
        self._assembler = SegmentAssembler(self.get_parameter("buffer_s").value)
        self._latency_ms = collections.deque(maxlen=LATENCY_WINDOW)
        self._counts = collections.Counter()
        self._last = "no ring-down yet"
        self._calibration: _Calibration | None = None
        self.create_subscription(MagnetometerBlock, "mows/raw", self._on_block, STREAM_QOS)
        self.create_subscription(ExcitationState, "mows/excitation", self._on_excitation, RESULT_QOS)
        self._fit_pub = self.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
        self._field_pub = self.create_publisher(FieldEstimate, "mows/field", RESULT_QOS)
        self._magnetic_pub = self.create_publisher(MagneticField, "mows/magnetic_field", STREAM_QOS)
        # A group of its own, reentrant: an awaiting calibration holds its group until it
        # returns. In the default group it would stop the stream that brings its ring-downs; in
        # a mutually exclusive one a second request would wait instead of being refused.
        self.create_service(Calibrate, "mows/estimator/calibrate", self._on_calibrate,
                            callback_group=ReentrantCallbackGroup())

    def _warm_up(self):
        """Compile the fit (or load it from numba's cache) before listening: that must not happen
        on the first real ring-down. Subscriptions and publishers come after, so a node that
        advertises its results is ready to produce them."""
        self.get_logger().info(f"fit kernels ready in {precompile(simulator=False):.1f} s")

    # --- parameters -------------------------------------------------------------------------
    def _param(self, name):
        return self.get_parameter(name).value

    def probe(self) -> Probe:
        return probe_of(self._param("probe_file"))

    def f00(self) -> tuple[float, float]:
        f00 = self._param("f00_hz")
        return (f00 if f00 > 0 else self.probe().f00_hz), self._param("f00_std_hz")

    def _options(self, theta0_rad: float) -> FitOptions:
        direction = (self._param("sensor_axis_a"), self._param("sensor_axis_b"))
        channels = self._param("channels")
        common = dict(sensor_direction=direction, min_periods=self._param("min_periods"),
                      max_chi2_dof=self._param("max_chi2_dof"))
        if self._param("lever_aware") and not self._param("theta0_free") and channels != "both":
            pair = FluxgatePair.paper(distance_m=self._param("sensor_distance_m"),
                                      spacing_m=self._param("sensor_spacing_m"), axis=(*direction, 0.0))
            return FitOptions.lever_aware(pair, self.probe(), theta0_rad, channels, **common)
        return FitOptions(channels=channels, theta0_free=self._param("theta0_free"), **common)

    # --- stream -----------------------------------------------------------------------------
    def _on_excitation(self, msg: ExcitationState):
        if msg.phase != ExcitationState.PHASE_RINGDOWN or (msg.tuning and not self._param("fit_tuning_ringdowns")):
            return
        arrived = time.monotonic()
        try:
            window = window_from_message(msg)
        except ValueError as error:
            self._counts["malformed_excitation"] += 1
            self.get_logger().warn(f"{error}: ignored")
            return
        for segment in self._assembler.announce(window):
            self._process(segment, arrived)

    def _on_block(self, msg: MagnetometerBlock):
        arrived = time.monotonic()
        try:
            block = block_from_message(msg)
        except ValueError as error:           # not samples a device could have sent: nothing usable
            self._counts["malformed_blocks"] += 1
            self.get_logger().warn(f"malformed MagnetometerBlock {msg.sequence}: {error}")
            return
        for segment in self._assembler.add_block(block):
            self._process(segment, arrived)

    def _process(self, segment, arrived: float):
        try:
            options = self._options(segment.window.theta0_rad)
        except ValueError as error:      # e.g. a sensing axis of (0, 0): no model to fit
            fit = failure(FitStatus.BAD_FIT, f"cannot build the signal model: {error}",
                          theta0_rad=segment.window.theta0_rad)
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
        self._latency_ms.append(1e3 * (time.monotonic() - arrived))
        self._counts[fit.status.name] += 1
        self._last = fit.report()
        if not fit.ok:
            self.get_logger().warn(f"cycle {segment.window.cycle_id} repeat {segment.window.repeat_index}: "
                                   f"{fit.report()}")

    # --- calibration ------------------------------------------------------------------------
    def _offer_to_calibration(self, frequency_hz: float, std_hz: float):
        calibration = self._calibration
        if calibration is not None and not calibration.finished.done():
            calibration.fits.append((frequency_hz, std_hz))
            if len(calibration.fits) >= calibration.wanted:
                calibration.finished.set_result(True)

    async def _on_calibrate(self, request: Calibrate.Request, response: Calibrate.Response):
        """Eq. 6 solved for f00: f00 = f/√(1 + m·B/kM) for each ring-down, then averaged."""
        probe = self.probe()
        ratio = 1.0 + probe.moment_am2 * request.reference_field_t / probe.spring_nm_per_rad
        if request.n_ringdowns < 1 or not (request.timeout_s > 0) or not ratio > 0:
            response.success = False
            response.message = (f"need n_ringdowns ≥ 1, timeout_s > 0 and a reference field above spring "
                                f"cancellation (−kM/m = {probe.cancellation_field_t * 1e3:.2f} mT)")
            return response
        if self._calibration is not None:
            response.success, response.message = False, "a calibration is already running: try again after it"
            return response
        calibration = self._calibration = _Calibration(request.n_ringdowns)
        timeout = self.create_timer(request.timeout_s, calibration.time_up)
        try:
            await calibration.finished
        finally:
            self.destroy_timer(timeout)
            self._calibration = None
        fits = np.array(calibration.fits, float).reshape(-1, 2)
        response.n_used = len(fits)
        if len(fits) < request.n_ringdowns:
            response.success = False
            response.message = f"only {len(fits)} of {request.n_ringdowns} OK ring-downs in {request.timeout_s} s"
            return response
        f00_each = fits[:, 0] / math.sqrt(ratio)
        spread = f00_each.std(ddof=1) / math.sqrt(len(fits)) if len(fits) > 1 else 0.0
        propagated = math.sqrt(np.sum((fits[:, 1] / math.sqrt(ratio)) ** 2)) / len(fits)
        response.f00_hz, response.f00_std_hz = float(f00_each.mean()), float(max(spread, propagated))
        # Out-of-range values (an f00 uncertainty above 10 Hz says the ring-downs were not of one
        # probe in one field) are refused by the parameters' ranges, with the reason.
        result = self.set_parameters_atomically([
            Parameter("f00_hz", Parameter.Type.DOUBLE, response.f00_hz),
            Parameter("f00_std_hz", Parameter.Type.DOUBLE, response.f00_std_hz)])
        response.success = result.successful
        response.message = result.reason or (f"f00 = {response.f00_hz:.6f} ± {response.f00_std_hz * 1e3:.4f} mHz "
                                             f"from {len(fits)} ring-downs")
        return response

    # --- health -----------------------------------------------------------------------------
    def health(self) -> Health:
        latency = np.array(self._latency_ms) if self._latency_ms else np.array([math.nan])
        failed = sum(v for k, v in self._counts.items() if k != "OK")
        missing = self._assembler.missing_samples
        level = DiagnosticStatus.OK if not (failed or missing) else DiagnosticStatus.WARN
        f00, f00_std = self.f00()
        return Health(level, self._last, {
            "fits_ok": self._counts["OK"], "fits_failed": failed,
            **{f"status_{k}": v for k, v in self._counts.items() if k != "OK"},
            "latency_p50_ms": float(np.percentile(latency, 50)), "latency_p99_ms": float(np.percentile(latency, 99)),
            "missing_samples": missing, "late_windows": self._assembler.late_windows,
            "blocks": self._assembler.blocks, "f00_hz": f00, "f00_std_hz": f00_std})


def main(args: list[str] | None = None) -> int:
    return run_node(EstimatorNode, args)
