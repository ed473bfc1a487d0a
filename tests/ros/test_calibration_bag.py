"""A calibration run on the simulated driver, recorded, gives the same constants offline
(``mows calibrate BAG``) as the calibration action gave online.

The graph is the real one: the driver (sim backend, the calibration bench's probe, recording),
the estimator fitting its ring-downs and the calibrator stepping the supply. Offline, the bag's
ring-downs are fitted by the same code from the same samples and paired with the supply current
the driver's /mows/supply states recorded, so the constants agree to rounding, not only within
their uncertainties. A real bag thus reproduces a calibration without the hardware.
"""

import math

import pytest
from action_msgs.msg import GoalStatus
from mows_msgs.action import CalibrateProbe
from rclpy.action import ActionClient

from mows.cli import main as cli
from mows.device.recording import bags
from mows.physics.probe import calibration_record
from mows_bringup.nodes import NODES
from node_processes import START_S, send_goal

pytestmark = pytest.mark.ros

NODE = {n.name: n for n in NODES}
CURRENTS = [0.0, 1.0, -1.0]
DRIVER = [
    "-p", "scenario:=calibration",
    "-p", "coil_setup:=helmholtz",
    "-p", "initial_frequency_hz:=125.5",
    "-p", "tuning_steps:=1",
    "-p", "gap_s:=0.3",
    "-p", "turn_settle_s:=0.3",
]  # fmt: skip


def stop(process) -> None:
    """SIGTERM, as ros2 launch stops a node: the driver closes its bag."""
    process.terminate()
    assert process.wait(timeout=60) == 0, process.log_path.read_text()


def test_a_recorded_calibration_gives_the_actions_constants_offline(ros, start, tmp_path, capsys):
    bag, online, offline = tmp_path / "run", tmp_path / "online.yaml", tmp_path / "offline.yaml"
    driver = start(*NODE["driver"].command([*DRIVER, "-p", f"record_path:={bag}"]))
    estimator = start(*NODE["estimator"].command([]))
    calibrator = start(*NODE["calibrator"].command(["-p", f"probe_output_file:={online}"]))
    client = ActionClient(ros.node, CalibrateProbe, "calibrator/calibrate_probe")
    ros.wait_for(client.server_is_ready, "the calibration action server", START_S)
    ros.wait_for_estimator_hearing()  # or the first ring-down may be over before it listens
    handle, done, _ = send_goal(ros, client, CalibrateProbe.Goal(currents_a=CURRENTS), result_bound_s=600.0)
    assert handle.accepted
    assert done.status == GoalStatus.STATUS_SUCCEEDED, done.result.message + calibrator.log_path.read_text()
    assert done.result.supply_at_zero
    for process in (calibrator, estimator, driver):
        stop(process)

    # What the driver recorded of the supply: zero as the goal arrived (the calibrator's check
    # that there is a supply), every commanded current, steady once reached, and zero at the end.
    # The plan runs the currents up at 0° and down at 180° (the stage turned once), so the
    # current at the turn is held, not set again.
    states = [m.message for m in bags.read_bag(bag, topics=["/mows/supply"])]
    assert [s.current_a for s in states if not s.ramping] == [0.0, *CURRENTS, *CURRENTS[-2::-1], 0.0]
    assert cli.main(["calibrate", str(bag), "-o", str(offline), "--scenario", "calibration"]) == 0
    printed = capsys.readouterr().out
    action = dict(zip(done.result.names, zip(done.result.values, done.result.stds)))
    constants = calibration_record(offline)["constants"]
    assert set(constants) == set(action), printed
    for name, (value, std) in action.items():
        assert math.isclose(constants[name]["value"], value, rel_tol=1e-9, abs_tol=1e-6 * std), (name, printed)
        assert math.isclose(constants[name]["std"], std, rel_tol=1e-6), (name, printed)
    assert calibration_record(online)["points"] == calibration_record(offline)["points"] == 2 * len(CURRENTS)
