"""The estimator node end to end: device-stamped blocks and ring-down announcements in, a fit
(with a status) for every ring-down out, field estimates only for good ones, and a node that
survives bad data. The node runs as its own process, as in the graph."""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.msg import ExcitationState, FieldEstimate, MagnetometerBlock, MagnetometerChannel, RingdownFit
from mows_msgs.srv import CalibrateF00
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue
from rcl_interfaces.srv import SetParameters
from sensor_msgs.msg import MagneticField

from mows.bench.estimator import AMPLITUDE_RAD, DAMPING_PER_S, KAPPA_T, PHASE_RAD
from mows.physics.frequency import frequency_shift_hz
from mows.physics.probe import PAPER_PROBE
from mows.physics.signal import signal_t
from mows.records import stamps
from mows_bringup.nodes import NODES
from mows_ros.qos import EXCITATION_QOS, RESULT_QOS, STREAM_QOS
from node_processes import assert_stops_cleanly

pytestmark = pytest.mark.ros

FS = 20_000.0
BLOCK = 500
EPOCH_S = 1_000.0
THETA0 = math.radians(20.0)
FIELD_T = 40e-6
F_TRUE = PAPER_PROBE.f00_hz + float(
    frequency_shift_hz(PAPER_PROBE.f00_hz, PAPER_PROBE.spring_nm_per_rad, PAPER_PROBE.moment_am2 * FIELD_T)
)


class Device:
    """A stand-in for the driver: publishes a continuous two-channel stream in blocks and
    announces ring-downs, all on one device clock."""

    def __init__(self, ros):
        self.ros = ros
        self.raw = ros.node.create_publisher(MagnetometerBlock, "/mows/raw", STREAM_QOS)
        self.excitation = ros.node.create_publisher(ExcitationState, "/mows/excitation", EXCITATION_QOS)
        self.index = 0
        self.sequence = 0
        self.cycle = 0
        self.rng = np.random.default_rng(0)

    def ringdown(self, seconds=0.5, corrupt=None, skip_block=None, announce=True, cancel_block=None):
        """Announce a ring-down starting at the current sample and stream it; with
        ``cancel_block``, its cycle is cancelled (IDLE announced) as that block begins."""
        self.cycle += 1
        n = int(seconds * FS)
        t = np.arange(n) / FS
        clean = signal_t(t, THETA0, AMPLITUDE_RAD, F_TRUE, PHASE_RAD, DAMPING_PER_S, KAPPA_T)
        near = 2 * clean + 5e-10 * self.rng.standard_normal(n)
        far = clean + 5e-10 * self.rng.standard_normal(n)
        if corrupt is not None:
            corrupt(near)
        if announce:
            self.excitation.publish(
                ExcitationState(
                    header=self.header(self.index),
                    phase=ExcitationState.PHASE_RINGDOWN,
                    phase_name="RINGDOWN",
                    cycle_id=self.cycle,
                    repeats=1,
                    theta0_rad=THETA0,
                    frequency_hz=F_TRUE * 0.998,
                    planned_duration_s=seconds,
                )
            )
        for k, start in enumerate(range(0, n, BLOCK)):
            if k == cancel_block:
                self.excitation.publish(
                    ExcitationState(header=self.header(self.index), phase=ExcitationState.PHASE_IDLE, phase_name="IDLE")
                )
            if k != skip_block:
                self.publish_block(near[start : start + BLOCK], far[start : start + BLOCK])
            self.index += BLOCK
            self.sequence += 1
        self.idle(5)  # the stream goes on after the window, as a device's does

    def idle(self, blocks):
        for _ in range(blocks):
            self.publish_block(np.zeros(BLOCK), np.zeros(BLOCK))
            self.index += BLOCK
            self.sequence += 1

    def header(self, index):
        msg = MagnetometerBlock().header
        stamps.set_seconds(msg.stamp, EPOCH_S + index / FS)
        msg.frame_id = "mows_fluxgates"
        return msg

    def publish_block(self, near, far, channels=None, sample_rate_hz=FS):
        """A block of the two channels ``near`` and ``far``, or of ``channels`` as given."""
        if channels is None:
            channels = [channel(data, len(data), i) for i, data in enumerate((near, far))]
        self.raw.publish(
            MagnetometerBlock(
                header=self.header(self.index),
                sequence=self.sequence,
                first_sample_index=self.index,
                sample_rate_hz=sample_rate_hz,
                range_t=1e-5,
                resolution_t=1e-10,
                channels=channels,
            )
        )
        # Give the estimator's best-effort queue time to drain, as a real 25 ms stream would.
        self.ros.executor.spin_once(timeout_sec=0.002)


def channel(data, flags, index=0):
    return MagnetometerChannel(frame_id=f"fluxgate_{index + 1}", field_t=list(data), saturated=[False] * flags)


@pytest.fixture
def estimator(ros, start):
    node = next(n for n in NODES if n.name == "estimator")
    # The stand-in device streams Eq. S11 data (a magnet turning in place), so the node is
    # told to fit that model rather than the lever-aware pickup of the real probe.
    process = start(*node.command(["-p", f"f00_hz:={PAPER_PROBE.f00_hz}", "-p", "lever_aware:=false"]))
    heard = {"fits": [], "fields": [], "magnetic": [], "diagnostics": {}}
    ros.node.create_subscription(RingdownFit, "/mows/ringdown", heard["fits"].append, RESULT_QOS)
    ros.node.create_subscription(FieldEstimate, "/mows/field", heard["fields"].append, RESULT_QOS)
    ros.node.create_subscription(MagneticField, "/mows/magnetic_field", heard["magnetic"].append, STREAM_QOS)
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics", lambda a: heard["diagnostics"].update((s.name, s) for s in a.status), 10
    )
    yield heard_device(ros, heard), heard, process
    assert_stops_cleanly(process)


def heard_device(ros, heard) -> Device:
    """A stand-in device the estimator has subscribed to and hears (``heard["diagnostics"]``
    is updated from /diagnostics)."""
    device = Device(ros)
    ros.wait_for(
        lambda: device.raw.get_subscription_count() and device.excitation.get_subscription_count(),
        "the estimator to subscribe",
    )

    def estimator_hears_the_stream():
        # Discovery is not symmetric: until the estimator has matched this publisher, best-effort
        # blocks are dropped. Stream until its diagnostics count received blocks.
        device.idle(1)
        status = heard["diagnostics"].get("/estimator")
        return status and any(kv.key == "blocks" and int(kv.value) > 0 for kv in status.values)

    ros.wait_for(estimator_hears_the_stream, "the estimator to receive blocks")
    return device


def test_a_ringdown_gives_a_fit_a_field_estimate_and_a_magnetic_field(ros, estimator):
    device, heard, _ = estimator
    device.ringdown()
    ros.wait_for(lambda: heard["fits"] and heard["fields"] and heard["magnetic"], "results")
    fit, field, magnetic = heard["fits"][0], heard["fields"][0], heard["magnetic"][0]
    assert fit.status == RingdownFit.STATUS_OK, fit.message
    assert abs(fit.frequency_hz - F_TRUE) < 4 * fit.frequency_std_hz
    assert fit.cycle_id == device.cycle and fit.header.frame_id == "mows_probe"
    assert len(fit.covariance) == len(fit.parameter_names) ** 2
    assert abs(field.field_along_axis_t - FIELD_T) < 4 * field.field_along_axis_std_t
    assert field.header.stamp == fit.header.stamp  # device clock, not receive time
    assert magnetic.magnetic_field.x == pytest.approx(field.field_along_axis_t)
    assert math.isnan(magnetic.magnetic_field.y) and math.isnan(magnetic.magnetic_field.z)
    assert magnetic.magnetic_field_covariance[0] == pytest.approx(field.field_along_axis_std_t**2)


@pytest.mark.parametrize(
    "corrupt, skip, status",
    [
        (lambda y: y.__setitem__(slice(2000, 2010), np.nan), None, RingdownFit.STATUS_INVALID_SAMPLES),
        (None, 7, RingdownFit.STATUS_DATA_GAP),
    ],
)
def test_bad_ringdowns_get_a_status_and_no_field(ros, estimator, corrupt, skip, status):
    device, heard, process = estimator
    device.ringdown(corrupt=corrupt, skip_block=skip)
    ros.wait_for(lambda: heard["fits"], "a fit result")
    assert heard["fits"][0].status == status and heard["fits"][0].message
    assert math.isnan(heard["fits"][0].frequency_hz)
    device.ringdown()  # and the node carries on
    ros.wait_for(lambda: len(heard["fits"]) == 2 and heard["fields"], "the next fit and its field")
    assert heard["fits"][1].status == RingdownFit.STATUS_OK
    assert len(heard["fields"]) == 1 and heard["fields"][0].cycle_id == heard["fits"][1].cycle_id
    assert process.poll() is None


def test_a_ringdown_cancelled_inside_gives_no_ok_fit_and_no_field(ros, estimator):
    """A cycle cancelled 0.3 s into its 0.5 s ring-down: the driver counts it as not recorded,
    and though the stream goes on through the whole window, its fit says why it is none."""
    device, heard, _ = estimator
    device.ringdown(cancel_block=round(0.3 * FS / BLOCK))
    ros.wait_for(lambda: heard["fits"], "a fit result")
    (fit,) = heard["fits"]
    assert fit.status == RingdownFit.STATUS_TOO_SHORT and "cut short after 0.30 s of 0.50 s" in fit.message
    device.ringdown()  # the next ring-down is fitted
    ros.wait_for(lambda: len(heard["fits"]) == 2 and heard["fields"], "the next fit and its field")
    assert heard["fits"][1].status == RingdownFit.STATUS_OK
    assert [f.cycle_id for f in heard["fields"]] == [heard["fits"][1].cycle_id]


def test_malformed_messages_do_not_stop_the_node(ros, estimator):
    device, heard, process = estimator
    zeros = np.zeros(BLOCK)
    malformed = [
        dict(channels=[channel(zeros, BLOCK), channel(zeros, BLOCK - 1)]),  # flags short in one
        dict(channels=[channel(zeros, 0), channel(zeros, 0)]),  # no flags at all
        dict(channels=[]),
        dict(sample_rate_hz=math.nan),
        dict(sample_rate_hz=0.0),
        dict(channels=[channel(zeros, BLOCK, i) for i in range(3)]),
    ]  # valid, one channel more
    for changes in malformed:
        device.publish_block(zeros, zeros, **changes)
        device.index += BLOCK  # a malformed block is lost to the estimator: a gap before the ring-down
        device.sequence += 1
    device.excitation.publish(
        ExcitationState(
            header=device.header(device.index),
            phase=ExcitationState.PHASE_RINGDOWN,
            planned_duration_s=math.nan,
            frequency_hz=112.0,
        )
    )
    device.ringdown()
    ros.wait_for(lambda: heard["fits"], "a fit after malformed input")
    assert heard["fits"][-1].status == RingdownFit.STATUS_OK and process.poll() is None
    name = "/estimator"
    ros.wait_for(
        lambda: (
            name in heard["diagnostics"]
            and {"status_malformed_excitation", "status_malformed_blocks"}
            <= {kv.key for kv in heard["diagnostics"][name].values}
        ),
        "diagnostics",
    )


def test_calibration_sets_f00_from_ringdowns_in_a_known_field(ros, estimator):
    device, heard, _ = estimator
    client = ros.node.create_client(CalibrateF00, "/estimator/calibrate")
    ros.wait_for(client.service_is_ready, "the calibration service")
    request = CalibrateF00.Request(n_ringdowns=3, reference_field_t=FIELD_T, timeout_s=60.0)
    futures = [client.call_async(request), client.call_async(request)]  # one too many: refused, not mixed
    ros.wait_for(lambda: any(f.done() for f in futures), "the second calibration's refusal")
    refused = next(f for f in futures if f.done())
    running = futures[1 - futures.index(refused)]
    assert not refused.result().success and "already running" in refused.result().message
    for _ in range(3):
        device.ringdown()
    response = ros.wait_for(lambda: running.done() and running.result(), "the calibration")
    assert response.success, response.message
    assert abs(response.f00_hz - PAPER_PROBE.f00_hz) < 4 * response.f00_std_hz
    assert response.n_used == 3


def test_a_calibration_without_enough_ringdowns_ends_at_its_timeout_and_frees_the_service(ros, estimator):
    device, _, _ = estimator
    client = ros.node.create_client(CalibrateF00, "/estimator/calibrate")
    ros.wait_for(client.service_is_ready, "the calibration service")
    starved = client.call_async(CalibrateF00.Request(n_ringdowns=2, reference_field_t=FIELD_T, timeout_s=0.5))
    response = ros.wait_for(lambda: starved.done() and starved.result(), "the timeout")
    assert not response.success and response.n_used == 0 and "only 0 of 2" in response.message
    again = client.call_async(CalibrateF00.Request(n_ringdowns=1, reference_field_t=FIELD_T, timeout_s=60.0))
    device.ringdown()
    response = ros.wait_for(lambda: again.done() and again.result(), "the next calibration")
    assert response.success and response.n_used == 1, response.message


def test_out_of_range_parameters_are_refused(ros, estimator):
    client = ros.node.create_client(SetParameters, "/estimator/set_parameters")
    ros.wait_for(client.service_is_ready, "the parameter service")
    bad = ParameterMsg(
        name="coil_off_skip_s", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=5.0)
    )
    future = client.call_async(SetParameters.Request(parameters=[bad]))
    result = ros.wait_for(lambda: future.done() and future.result(), "set_parameters")
    assert not result.results[0].successful and "coil_off_skip_s" in result.results[0].reason
