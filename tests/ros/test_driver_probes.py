"""The driver node on a scene of several probes (three_probes: 100, 112.5, 125 Hz on one shared
stage, at home orientations 0, 40 and 80°).

Requirement: a RunCycle drives the multi-probe simulator; each excitation and its ring-down list
the probes it rings with their tones and their own θ0 (home + the stage's angle) on
/mows/excitation; the samples stream without a gap; under a 0.25 A cap the three tones are
split into groups, and the coil currents the device carried never exceed the cap;
/diagnostics says how many probes the device rings.
"""

import math

import pytest
from mows_msgs.msg import ExcitationState, MagnetometerBlock
from mows_msgs.srv import RunCycle
from rclpy.qos import QoSProfile, ReliabilityPolicy

from mows.device.cycle.phases import Phase
from mows.records import stamps
from mows.sim.scenario import load_scenario
from mows_bringup.nodes import NODES
from mows_ros.qos import EXCITATION_QOS

pytestmark = [pytest.mark.ros, pytest.mark.xdist_group("realtime")]  # the simulator paced in real time

CAP_A = 0.25
STAGE_RAD = 0.4
ARGS = [
    *("-p", "scenario:=three_probes", "-p", f"coil_current_cap_a:={CAP_A}", "-p", f"excitation_current_a:={CAP_A}"),
    *("-p", "excite_s:=0.3", "-p", "ringdown_s:=0.3", "-p", "turn_settle_s:=0.1", "-p", "tuning_steps:=0"),
]
RAW_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)


def stamp_ns(message) -> int:
    return stamps.nanoseconds(message.header.stamp)


def test_a_cycle_of_three_probes_lists_them_on_each_excitation_and_keeps_the_cap(ros, start):
    blocks: list[MagnetometerBlock] = []
    states: list[ExcitationState] = []
    ros.node.create_subscription(MagnetometerBlock, "/mows/raw", blocks.append, RAW_QOS)
    ros.node.create_subscription(ExcitationState, "/mows/excitation", states.append, EXCITATION_QOS)
    diagnostics = ros.diagnostics_of("/driver")
    run_cycle = ros.node.create_client(RunCycle, "/driver/run_cycle")
    start(*NODES[0].command(ARGS))
    ros.wait_for(lambda: blocks and diagnostics.get("probes") == "3", "the stream and the device's three probes")
    ros.wait_for(lambda: run_cycle.service_is_ready(), "the run_cycle service")
    future = run_cycle.call_async(RunCycle.Request(theta0_rad=STAGE_RAD, repeats=1, tuning_steps=-1, gap_s=0.1))
    response = ros.wait_for(lambda: future.done() and future.result(), "the cycle's response")
    assert response.success, response.message
    groups = response.ringdowns_recorded  # one repeat: one ring-down per group
    assert groups >= 2  # the cap split the three tones
    ros.wait_for(lambda: states and states[-1].phase == Phase.IDLE and states[-1].cycle_id == 1, "the cycle's end")

    ringing = [s for s in states if s.phase in (Phase.EXCITING, Phase.RINGDOWN)]
    assert [Phase(s.phase) for s in ringing] == [Phase.EXCITING, Phase.RINGDOWN] * groups
    assert sorted(i for s in ringing[::2] for i in s.probe_ids) == [0, 1, 2]
    home = [p.pose.theta0_rad for p in load_scenario("three_probes").placed_probes()]
    f00 = [100.0, 112.5, 125.0]
    for s in ringing:
        ids = list(s.probe_ids)
        assert list(s.probe_frequency_hz) == pytest.approx([f00[i] for i in ids], abs=1e-9)
        assert list(s.probe_theta0_rad) == pytest.approx([home[i] + STAGE_RAD for i in ids], abs=1e-12)
        assert s.theta0_rad == STAGE_RAD and s.coils_on == (s.phase == Phase.EXCITING)
        assert all(0.0 <= a <= CAP_A for a in s.coil_current_amplitude_a)
    assert home[1] == pytest.approx(math.radians(40.0)) and home[2] == pytest.approx(math.radians(80.0))
    assert all(not s.probe_ids for s in states if s.phase in (Phase.IDLE, Phase.SETTLING, Phase.GAP))

    end_ns = stamp_ns(ringing[-1]) + 300_000_000  # the last ring-down's 0.3 s
    ros.wait_for(lambda: stamp_ns(blocks[-1]) >= end_ns, "the last ring-down's samples")
    firsts = [b.first_sample_index for b in blocks]
    lengths = [len(b.channels[0].field_t) for b in blocks]
    assert [a + n for a, n in zip(firsts, lengths)][:-1] == firsts[1:], "samples missing between blocks"
    ros.wait_for(lambda: float(diagnostics.get("peak_coil_current_a", 0.0)) > 0.0, "the device's peak current")
    assert 0.0 < float(diagnostics["peak_coil_current_a"]) <= CAP_A
