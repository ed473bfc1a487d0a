"""The estimator node: ROS side of ring-down fitting and inversion (``mows.ringdown``,
``mows.inversion``). Translates only: the estimation lives in ``mows``."""
from mows_ros.node import MowsNode
from mows_ros.params import ParamSpec
from mows_ros.process import run_node

NODE_NAME = "estimator"

PARAMETERS = (
    ParamSpec(
        "probe_file",
        "",
        "probe constants YAML (mows.probe.Probe.from_yaml); empty: the paper's probe "
        "(mows.probe.PAPER_PROBE)",
    ),
)


class EstimatorNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)


def main(args: list[str] | None = None) -> int:
    return run_node(EstimatorNode, args)
