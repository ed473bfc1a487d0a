"""The operator of a stage without a motor, from the terminal: ``mows-graph`` with the mapper's
and the calibrator's ``orientation: manual`` says each turn a sweep or a calibration asks for,
with its θ0, in its own output; Enter typed into its terminal confirms the turn, and so does
``mows-confirm-orientation`` from a second terminal. With no turn awaited,
``mows-confirm-orientation`` says so and exits 1.

Requirement: every orientation of the sweep is asked for once, in order, and measured once
confirmed (the sweep succeeds with a point per orientation); a calibration on the same graph,
its prompts answered by Enter, ends with the supply at zero after at most 4 turns for its wiring
(every current at 0°, then every current at 180°: 2); each confirmation is answered with the θ0
it confirmed; the graph still stops cleanly on SIGINT."""

import math
import signal
import subprocess

import pytest
from mows_msgs.action import CalibrateProbe, RotationSweep
from rclpy.action import ActionClient

from node_processes import log

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

ANGLES_DEG = (0, 60, 120, 180, 240)
QUICK = ["-p", "driver:tuning_steps:=0", "-p", "driver:gap_s:=0.1", "-p", "driver:turn_settle_s:=0.1"]
BENCH = ["-p", "driver:scenario:=calibration", "-p", "driver:coil_setup:=helmholtz"]  # a supply to step
MANUAL = ["-p", "mapper:orientation:=manual", "-p", "calibrator:orientation:=manual"]
CURRENTS_A = [0.0, 1.0, -1.0]
MAX_TURNS_PER_WIRING = 4


def enter(graph, confirmed: str, ros) -> None:
    """Press Enter in the graph's terminal; wait for its word that ``confirmed`` was confirmed."""
    count = log(graph).count(confirmed)
    graph.stdin.write(b"\n")
    graph.stdin.flush()
    ros.wait_for(lambda: log(graph).count(confirmed) > count, f"the graph's word: {confirmed}", 60.0)


def test_each_turn_is_asked_in_the_graph_s_terminal_and_confirmed_by_enter_or_the_command(ros, start, tmp_path):
    output = ["-p", f"calibrator:probe_output_file:={tmp_path / 'probe.yaml'}"]
    graph = start("mows-graph", "--ros-args", *MANUAL, *QUICK, *BENCH, *output, stdin=subprocess.PIPE)
    client = ActionClient(ros.node, RotationSweep, "/mapper/rotation_sweep")
    ros.wait_for(client.server_is_ready, "the sweep action", 300.0)
    ros.wait_for(lambda: "press Enter here" in log(graph), "the graph's word on the manual stage", 300.0)
    ros.wait_for_estimator_hearing()
    goal = RotationSweep.Goal(theta0_rad=[math.radians(a) for a in ANGLES_DEG], repeats_per_angle=1)
    sent = client.send_goal_async(goal)
    handle = ros.wait_for(lambda: sent.done() and sent.result(), "the goal's answer")
    result = handle.get_result_async()
    for k, degrees in enumerate(ANGLES_DEG):
        asked = f"turn the probe to θ0 = {degrees:g}° and confirm"
        ros.wait_for(lambda asked=asked: asked in log(graph), f"the prompt for {degrees}°", 120.0)
        assert log(graph).count("turn the probe to θ0") == k + 1, log(graph)
        if k == 2:  # from a second terminal
            other = subprocess.run(["mows-confirm-orientation"], capture_output=True, text=True, timeout=60)
            assert other.returncode == 0 and f"mapper: θ0 = {degrees:g}° confirmed" in other.stdout, other
        else:
            enter(graph, f"mapper: θ0 = {degrees:g}° confirmed", ros)
    done = ros.wait_for(lambda: result.done() and result.result(), "the sweep", 300.0)
    assert done.result.success, done.result.message
    assert done.result.decomposition.n_points == len(ANGLES_DEG)

    calibration = ActionClient(ros.node, CalibrateProbe, "/calibrator/calibrate_probe")
    ros.wait_for(calibration.server_is_ready, "the calibration action")
    sent = calibration.send_goal_async(CalibrateProbe.Goal(currents_a=CURRENTS_A))
    result = ros.wait_for(lambda: sent.done() and sent.result(), "the goal's answer").get_result_async()
    turns = 0
    while not result.done():
        asked = [line for line in log(graph).splitlines() if "[calibrator]" in line and "turn the probe to" in line]
        if len(asked) > turns:
            degrees = asked[turns].split("θ0 = ")[1].split("°")[0]
            enter(graph, f"calibrator: θ0 = {degrees}° confirmed", ros)
            turns += 1
        ros.executor.spin_once(timeout_sec=0.1)
    assert result.result().result.success and result.result().result.supply_at_zero, result.result().result.message
    assert 1 <= turns <= MAX_TURNS_PER_WIRING, log(graph)
    idle = subprocess.run(["mows-confirm-orientation"], capture_output=True, text=True, timeout=60)
    assert idle.returncode == 1 and "mapper: no turn of the probe is awaited" in idle.stdout, idle
    graph.send_signal(signal.SIGINT)
    assert graph.wait(timeout=60) == 0, log(graph)
