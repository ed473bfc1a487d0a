"""The estimator node with three probes in each window: one stream from the shared fluxgates,
one RingdownFit per probe, each with its probe_id and frame, and per-probe counts on
/diagnostics.

Requirement: three probes 5 cm apart (112.5, 125 and 101 Hz), ringing down together in each
other's fields (the coupled simulation) and seen through the paper's fluxgate pair as the
driver streams them, come back from the node each at its coupled first-principles frequency
within 4σ, with Δf counted from its own f00. The node runs as its own process, as in the graph.
"""

import math

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.msg import ExcitationState, RingdownFit
from mows_msgs.srv import CalibrateF00

from mows.physics.coupling import PlacedProbe, coupled_frequencies_hz
from mows.physics.fluxgate import FluxgatePair
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE as P
from mows.physics.sources import UniformField
from mows.sim.readings import swinging_pickup_t
from mows_bringup.nodes import NODES
from mows_ros.qos import RESULT_QOS
from node_processes import assert_stops_cleanly
from scenes import scene_device
from test_estimator_node import FS, Device, heard_device

pytestmark = [pytest.mark.ros, pytest.mark.xdist_group("realtime")]

THETA0 = math.radians(20.0)
SCENE = UniformField([20e-6, 10e-6, 0.0])
SPRING_SCALES = (1.0, 1.235, 0.806)  # f00 112.5, 125.0 and 101.0 Hz
POSITIONS_M = ((0.0, 0.0, 0.0), (0.0, 0.05, 0.0), (0.0, -0.05, 0.0))
DURATION_S = 0.5


@pytest.fixture(scope="module")
def three_probes():
    """The probes, their coupled frequencies, and the pair's samples (n, 2) of one ring-down."""
    placed = [
        PlacedProbe(P.replace(spring_nm_per_rad=P.spring_nm_per_rad * s), Pose(theta0_rad=THETA0, magnet_position_m=r))
        for s, r in zip(SPRING_SCALES, POSITIONS_M)
    ]
    n = int(DURATION_S * FS)
    start = [math.radians(a) for a in (4.0, 3.5, 4.0)]  # small swings: the model is at zero amplitude
    theta, _ = scene_device(placed, [SCENE], FS).ring_down(start, n)
    pair = FluxgatePair.paper()
    samples = swinging_pickup_t(pair, placed, theta)
    samples = samples + 1e-10 * np.random.default_rng(5).standard_normal(samples.shape)
    return placed, coupled_frequencies_hz(placed, SCENE), samples


def probes_parameter(placed) -> str:
    entries = (
        f"{k}: {{f00_hz: {p.probe.f00_hz!r}, position_m: [{', '.join(repr(x) for x in p.pose.magnet_position_m)}]}}"
        for k, p in enumerate(placed)
    )
    return "{" + ", ".join(entries) + "}"


def ring_down(device: Device, samples: np.ndarray, **announced) -> None:
    """Announce a ring-down at the device's present sample (at THETA0 and f00 unless
    ``announced`` says otherwise) and stream ``samples`` in blocks."""
    device.cycle += 1
    header = device.header(device.index)
    device.excitation.publish(
        ExcitationState(
            header=header,
            phase=ExcitationState.PHASE_RINGDOWN,
            phase_name="RINGDOWN",
            cycle_id=device.cycle,
            repeats=1,
            planned_duration_s=DURATION_S,
            **({"theta0_rad": THETA0, "frequency_hz": P.f00_hz} | announced),
        )
    )
    block = 500
    for start in range(0, len(samples), block):
        device.publish_block(samples[start : start + block, 0], samples[start : start + block, 1])
        device.index += block
        device.sequence += 1
    device.idle(5)


def started_estimator(ros, start, placed):
    """The estimator node told of ``placed``, a stand-in device it hears, what it publishes
    (``heard``), and its process."""
    node = next(n for n in NODES if n.name == "estimator")
    # Quoted: a -p value is YAML, and the mapping is the parameter's string.
    process = start(*node.command(["-p", f"probes:='{probes_parameter(placed)}'"]))
    heard = {"fits": [], "diagnostics": {}}
    ros.node.create_subscription(RingdownFit, "/mows/ringdown", heard["fits"].append, RESULT_QOS)
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics", lambda a: heard["diagnostics"].update((s.name, s) for s in a.status), 10
    )
    return heard_device(ros, heard), heard, process


@pytest.fixture
def estimator(ros, start, three_probes):
    device, heard, process = started_estimator(ros, start, three_probes[0])
    yield device, heard
    assert_stops_cleanly(process)


def test_each_probe_gets_its_fit_at_its_coupled_frequency(ros, estimator, three_probes):
    device, heard = estimator
    placed, coupled_hz, samples = three_probes
    ring_down(device, samples)
    ros.wait_for(lambda: len(heard["fits"]) == 3, "three fits")
    fits = sorted(heard["fits"], key=lambda f: f.probe_id)
    assert [f.probe_id for f in fits] == [0, 1, 2]
    for fit, p, expected in zip(fits, placed, coupled_hz):
        assert fit.status == RingdownFit.STATUS_OK, fit.message
        assert fit.header.frame_id == f"mows_probe_{fit.probe_id}" and fit.cycle_id == device.cycle
        assert abs(fit.frequency_hz - expected) < 4 * fit.frequency_std_hz, (fit.probe_id, fit.frequency_hz, expected)
        assert fit.frequency_shift_hz == pytest.approx(fit.frequency_hz - p.probe.f00_hz, abs=1e-9)
    # The neighbours are seen: the first probe's line is many σ from where it would be alone.
    alone_hz = coupled_frequencies_hz(placed[:1], SCENE)[0]
    assert abs(fits[0].frequency_hz - alone_hz) > 5 * fits[0].frequency_std_hz

    def counted():
        status = heard["diagnostics"].get("/estimator")
        values = {kv.key: kv.value for kv in status.values} if status else {}
        return all(values.get(f"probe_{k}_fits_ok") == "1" for k in range(3))

    ros.wait_for(counted, "per-probe counts on /diagnostics")


def test_the_f00_calibration_is_refused_with_several_probes(ros, estimator):
    client = ros.node.create_client(CalibrateF00, "/estimator/calibrate")
    ros.wait_for(client.service_is_ready, "the calibration service")
    future = client.call_async(CalibrateF00.Request(n_ringdowns=1, reference_field_t=1e-5, timeout_s=5.0))
    response = ros.wait_for(lambda: future.done() and future.result(), "the refusal")
    assert not response.success and "3 probes are listed" in response.message
