"""A serial device that dies mid-cycle: the driver logs the loss and the recovery, and the
cycle cut by it ends FAULT, published and recorded in the bag (the record of what happened
must survive the very failure it records)."""

import signal
import sys

import pytest
from mows_msgs.srv import RunCycle

from mows.device.cycle.phases import Phase
from mows.device.recording import bags
from mows_bringup.nodes import NODES
from node_processes import log
from test_driver_node import QUICK_CYCLES, Listener

pytestmark = pytest.mark.ros


def start_emulator(start, link):
    return start(sys.executable, "-m", "mows.device.serial.emulator", "--link", str(link))


@pytest.mark.xdist_group("realtime")  # the device emulator's real-time threads
def test_a_device_killed_in_a_ring_down_ends_the_cycle_fault_in_the_bag(start, ros, tmp_path):
    listen = Listener(ros)
    link, bag = tmp_path / "device", tmp_path / "recording"
    emulator = start_emulator(start, link)
    ros.wait_for(link.is_symlink, "the emulator's link")
    driver = start(
        *NODES[0].command(
            ["-p", "backend:=serial", "-p", f"serial_port:={link}", "-p", f"record_path:={bag}", *QUICK_CYCLES]
        )
    )
    ros.wait_for(lambda: len(listen.blocks) >= 10, "blocks from the emulated device")
    cycle = listen.call(listen.run_cycle, RunCycle.Request(theta0_rad=0.0, repeats=3, tuning_steps=0, gap_s=0.5))
    ros.wait_for(lambda: Phase.RINGDOWN in listen.phases(1), "the first ring-down")
    emulator.send_signal(signal.SIGKILL)
    response = listen.result(cycle)
    assert not response.success, response.message
    ros.wait_for(lambda: listen.phases(1)[-1] == Phase.FAULT, "the cycle's FAULT")
    ros.wait_for(lambda: "link lost" in log(driver), "the driver to log the loss")
    link.unlink()  # the killed emulator's link, left behind: the new one is made only where nothing is
    restarted = start_emulator(start, link)
    ros.wait_for(lambda: "link up" in log(driver).split("link lost")[-1], "the driver to log the recovery")
    driver.send_signal(signal.SIGTERM)
    assert driver.wait(timeout=30) == 0, log(driver)
    restarted.terminate()
    recorded = [m.message for m in bags.read_bag(bag) if m.msgtype == "mows_msgs/msg/ExcitationState"]
    cycle_phases = [Phase(s.phase) for s in recorded if s.cycle_id == 1]
    assert Phase.RINGDOWN in cycle_phases and cycle_phases[-1] == Phase.FAULT, cycle_phases
    assert "Logger severity" not in log(driver)
