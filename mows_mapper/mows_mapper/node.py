"""The mapper node: ROS side of rotation sweeps (``mows.sweep``) and the model lab
(``mows.lab``). Translates only: the decomposition lives in ``mows``."""
from mows_ros.node import MowsNode
from mows_ros.params import ParamSpec
from mows_ros.process import run_node

NODE_NAME = "mapper"

# RunCycle.repeats is an int32: a larger count could not be requested from the driver.
MAX_REPEATS = 2**31 - 1

PARAMETERS = (
    ParamSpec(
        "repeats_per_angle",
        5,
        "ring-downs recorded at each orientation of a rotation sweep whose goal asks for 0",
        range=(1, MAX_REPEATS),
    ),
)


class MapperNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)


def main(args: list[str] | None = None) -> int:
    return run_node(MapperNode, args)
