"""The driver node as a process on the simulated bench (``backend:=nidaqmx``, ``supply:=scpi``,
``daq_simulated:=true``: NI's ``nidaqmx`` on the simulated card in wall-clock time, the NGM202 on
pyvisa-sim), its supply set to 0.5 A. Requirement: a lifecycle deactivate, the emergency stop and
a Ctrl-C of mows-graph each leave the supply at 0 A with its output off, as the instrument reads
them back (``MEAS:CURR?``, ``OUTP?``): on the driver's /diagnostics while it runs, in its last
log line once it has exited. Every wait ends as soon as its condition holds.

And the bench for one person: in mows-graph on the simulated bench, whose stage is turned by
hand, a calibration on the unipolar supply runs end to end with each turn it asks for answered
by Enter in mows-graph's terminal (the simulated operator turns the simulated probe as asked), at
most 4 turns for the wiring, and ends with the supply at zero; the Ctrl-C comes after it."""

import re
import shlex
import signal
import subprocess
import time
from pathlib import Path

import pytest
from lifecycle_msgs.msg import Transition
from mows_msgs.action import CalibrateProbe
from mows_msgs.srv import EmergencyStop, SetFieldCurrent
from rclpy.action import ActionClient

from mows.device.instruments.scpi import load_supply_file
from mows_bringup.lifecycle import BOUND_S, LifecycleClient
from mows_bringup.nodes import NODES
from node_processes import WAIT_S, assert_stops_cleanly, log

# The card's clock is the wall clock: a worker starved for the output lead underflows it.
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

BENCH = {"backend": "nidaqmx", "supply": "scpi", "daq_simulated": "true"}
CURRENT_A = 0.5
CALIBRATION_CURRENTS_A = [0.0, 1.0, 2.0]  # the NGM202 is unipolar: θ0 + 180° gives the other sign
MAX_TURNS_PER_WIRING = 4
SUPPLY = load_supply_file()  # the paper's NGM202: the read-back's stated accuracy
# The driver's last word on the supply: as it read back, settled, after its ramp to zero and switch-off.
CLOSED = re.compile(r"\[driver\]: device closed: supply (\w+) at (\S+) A \(read back\)")


class Bench:
    """What the test node hears of the driver on the simulated bench, and its services."""

    def __init__(self, ros):
        self.ros = ros
        self.diagnostics = ros.diagnostics_of("/driver")
        self.supply = ros.node.create_client(SetFieldCurrent, "/driver/set_field_current")
        self.estop = ros.node.create_client(EmergencyStop, "/driver/emergency_stop")

    def call(self, client, request):
        self.ros.wait_for(client.service_is_ready, f"the service {client.srv_name}")
        future = client.call_async(request)
        return self.ros.wait_for(lambda: future.done() and future.result(), "the service's response")

    def reads_back(self, current_a: float, output: str) -> bool:
        """Whether the supply reads back ``current_a`` (within its stated accuracy) and ``output``."""
        values = self.diagnostics
        if values.get("supply_output") != output:
            return False
        return abs(float(values["supply_readback_a"]) - current_a) <= SUPPLY.readback_tolerance_a(current_a)

    def wait_until(self, current_a: float, output: str, bound_s: float = WAIT_S) -> None:
        what = f"the supply read back at {current_a} A, output {output}"
        self.ros.wait_for(lambda: self.reads_back(current_a, output), what, bound_s)

    def set_current(self, current_a: float, bound_s: float = WAIT_S) -> None:
        response = self.call(self.supply, SetFieldCurrent.Request(current_a=current_a))
        assert response.success, response.message
        self.wait_until(current_a, "on", bound_s)


@pytest.fixture
def bench(ros):
    return Bench(ros)


@pytest.fixture
def bench_driver(start):
    """The driver alone on the simulated bench, active."""
    return start(*NODES[0].command([arg for name, value in BENCH.items() for arg in ("-p", f"{name}:={value}")]))


def assert_closed_at_zero_and_off(process) -> None:
    """The driver's last word on the supply: off at 0 A, as read back."""
    closed = CLOSED.search(log(process))
    assert closed, log(process)
    output, current_a = closed.group(1), float(closed.group(2))
    assert output == "off" and abs(current_a) <= SUPPLY.readback_tolerance_a(0.0), closed.group(0)


def documented_start(marker: str) -> list[str]:
    """The driver's start command that docs/hardware.md prints with ``marker``, as a shell reads it."""
    text = (Path(__file__).parents[2] / "docs" / "hardware.md").read_text()
    blocks = re.findall(r"^```\w*\n(.*?)^```$", text, re.S | re.M)
    (block,) = [b for b in blocks if b.startswith("install/mows_driver/") and marker in b]
    return shlex.split(block.replace("\\\n", " "))


def test_the_documented_start_command_starts_the_driver(bench, start):
    """The rehearsal's command as printed (from the repository, as the docs say), and the bench's
    the same but for its supply's address."""
    bench_command = documented_start("supply_resource:=")
    command = documented_start("daq_simulated:=true")
    assert bench_command[:8] == command[:8] and Path(command[0]).is_file()
    driver = start(*command)
    bench.set_current(CURRENT_A, BOUND_S)  # active, on the simulated bench with its supply
    assert_stops_cleanly(driver)
    assert_closed_at_zero_and_off(driver)


def test_a_deactivate_leaves_the_supply_at_zero_and_off(bench, bench_driver):
    bench.set_current(CURRENT_A)
    lifecycle = LifecycleClient([], give_up=lambda: None)
    try:
        assert lifecycle.transition("driver", Transition.TRANSITION_DEACTIVATE, "inactive")
    finally:
        lifecycle.close()
    bench.wait_until(0.0, "off")
    assert bench.diagnostics["lifecycle_state"] == "inactive"
    assert_stops_cleanly(bench_driver)
    assert_closed_at_zero_and_off(bench_driver)


def test_the_emergency_stop_leaves_the_supply_at_zero_and_off(bench, bench_driver):
    bench.set_current(CURRENT_A)
    stop = bench.call(bench.estop, EmergencyStop.Request(engage=True, reason="test"))
    assert stop.success and stop.latched
    bench.wait_until(0.0, "off")
    assert bench.diagnostics["estop_latched"] == "True"
    assert_stops_cleanly(bench_driver)
    assert_closed_at_zero_and_off(bench_driver)


def calibrate_by_hand(bench, graph) -> int:
    """A calibration through the graph, each turn it asks for answered by Enter in the graph's
    terminal; the number of turns."""
    client = ActionClient(bench.ros.node, CalibrateProbe, "/calibrator/calibrate_probe")
    bench.ros.wait_for(client.server_is_ready, "the calibration action")
    bench.ros.wait_for_estimator_hearing()
    sent = client.send_goal_async(CalibrateProbe.Goal(currents_a=CALIBRATION_CURRENTS_A))
    result = bench.ros.wait_for(lambda: sent.done() and sent.result(), "the goal's answer").get_result_async()
    turns, deadline = 0, time.monotonic() + BOUND_S
    while not result.done():
        assert time.monotonic() < deadline, log(graph)
        asked = [line for line in log(graph).splitlines() if "[calibrator]" in line and "turn the probe to" in line]
        if len(asked) > turns:
            confirmed = f"calibrator: θ0 = {asked[turns].split('θ0 = ')[1].split('°')[0]}° confirmed"
            graph.stdin.write(b"\n")
            graph.stdin.flush()
            bench.ros.wait_for(lambda c=confirmed: c in log(graph), f"the graph's word: {confirmed}")
            turns += 1
        bench.ros.executor.spin_once(timeout_sec=0.1)
    done = result.result().result
    assert done.success and done.supply_at_zero, (done.message, log(graph))
    return turns


def test_a_hand_turned_calibration_then_a_ctrl_c_of_mows_graph_leave_the_supply_at_zero_and_off(bench, start, tmp_path):
    overrides = {**{f"driver:{name}": value for name, value in BENCH.items()}, "mapper:orientation": "manual"}
    overrides["calibrator:orientation"] = "manual"  # the bench's stage is turned by hand
    overrides.update({"driver:tuning_steps": "0", "driver:turn_settle_s": "0.2", "driver:gap_s": "0.1"})  # quick
    overrides["calibrator:probe_output_file"] = str(tmp_path / "calibrated_probe.yaml")  # not the working directory
    rules = [a for rule in overrides.items() for a in ("-p", ":=".join(rule))]
    graph = start("mows-graph", "--ros-args", *rules, stdin=subprocess.PIPE)
    # Bounded as mows-graph bounds it: configuring compiles, minutes on a loaded machine.
    bench.ros.wait_for(lambda: "every node is active" in log(graph) or graph.poll() is not None, "bring-up", BOUND_S)
    assert 1 <= calibrate_by_hand(bench, graph) <= MAX_TURNS_PER_WIRING
    bench.set_current(CURRENT_A)
    graph.send_signal(signal.SIGINT)
    assert graph.wait(timeout=WAIT_S) == 0, log(graph)
    assert_closed_at_zero_and_off(graph)
