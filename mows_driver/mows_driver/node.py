"""The driver node: ROS side of the device (``mows.simulator``, the serial link, a bag).

Translates only: device access and the measurement cycle live in ``mows``.
"""
from mows_ros.node import MowsNode
from mows_ros.params import ParamSpec
from mows_ros.process import run_node

NODE_NAME = "driver"

PARAMETERS = (
    ParamSpec(
        "backend",
        "sim",
        "where magnetometer blocks come from: sim (the simulator), serial (the device on a "
        "serial port), bag (a recorded rosbag2 MCAP bag)",
        choices=("sim", "serial", "bag"),
    ),
    ParamSpec(
        "scenario",
        "",
        "simulator scenario for backend sim: a YAML file, or the name of one shipped in "
        "mows/scenarios",
    ),
    ParamSpec(
        "coil_current_cap_a",
        10.0,
        "hard limit on the peak current of any excitation coil, A; fixed at start-up",
        read_only=True,
    ),
    ParamSpec(
        "block_duration_s",
        0.025,
        "length of one MagnetometerBlock on /mows/raw, s",
        range=(0.01, 0.05),
    ),
)


class DriverNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)


def main(args: list[str] | None = None) -> int:
    return run_node(DriverNode, args)
