"""The graph's nodes and what each is started with: its package and console script, its parameter
file (share/<package>/config/<node>.yaml), and the checks that ``mows-graph``'s ROS arguments pass
before any node starts (a parameter without a node's prefix, a prefix or name no node has, a
driver that cannot turn the stage with a node that would turn it).
"""

import importlib
from dataclasses import dataclass
from pathlib import Path

import yaml
from ament_index_python.packages import get_package_prefix, get_package_share_directory

from mows_bringup.confirm import TURNING_NODES
from mows_ros.params import (
    ROS_OWN,
    nearest_hint,
    prefixed_overrides,
    renamed_to,
    ros_argument_values,
    unknown_name_hint,
)
from mows_ros.process import arguments_problem


@dataclass(frozen=True)
class GraphNode:
    """A node of the graph: its ROS name, package and console script."""

    name: str
    package: str
    executable: str
    realtime: bool = False  # on the ring-down path: --realtime-priority applies to it

    def config_path(self) -> str:
        share = Path(get_package_share_directory(self.package))
        return str(share / "config" / f"{self.name}.yaml")

    def command(self, ros_args: list[str], autostart: bool = True) -> list[str]:
        """The node alone, active once it has configured itself (``--autostart``); with
        ``autostart=False`` unconfigured, for a supervisor to bring up."""
        # Where ros2 run and launch_ros look for an ament_python console script.
        script = Path(get_package_prefix(self.package)) / "lib" / self.package / self.executable
        own = ["--autostart"] if autostart else []
        return [str(script), *own, "--ros-args", "--params-file", self.config_path(), *ros_args]


NODES = (  # in data-flow order: the order of activation
    GraphNode("driver", "mows_driver", "mows_driver", realtime=True),
    GraphNode("estimator", "mows_estimator", "mows_estimator", realtime=True),
    GraphNode("mapper", "mows_mapper", "mows_mapper"),
    GraphNode("calibrator", "mows_calibrator", "mows_calibrator"),
)
VIZ = GraphNode("viz", "mows_viz", "mows_viz")  # with --foxglove, after the others
FOXGLOVE_PORT = 8765  # Foxglove's default for a WebSocket connection


def foxglove_arguments(port: int) -> list[str]:
    """The viz node's ROS arguments for ``--foxglove=port``: the port and the shipped mount."""
    mount = Path(get_package_share_directory("mows_bringup")) / "urdf" / "mows_probe_mount.urdf"
    return ["-p", f"{VIZ.name}:port:={port}", "-p", f"{VIZ.name}:mount_file:={mount}"]


def graph_nodes(foxglove: bool) -> tuple[GraphNode, ...]:
    return (*NODES, VIZ) if foxglove else NODES


def parameter_rule_problem(rule: str) -> str | None:
    """Why ``-p rule``, given to every node, is refused: without a node's prefix every node but
    one would stop on it, a prefix or a name no node has reaches none. None when it is fine."""
    target = rule.partition(":=")[0]
    prefix, colon, name = target.rpartition(":")
    names = [node.name for node in (*NODES, VIZ)]
    if "/" in prefix:
        return None  # a fully qualified node name: rcl matches it, the node checks the name
    if name in ROS_OWN and (not colon or prefix in names):
        return None  # every node has it (use_sim_time): for all of them, or for the one named
    tables = {node.name: importlib.import_module(f"{node.package}.parameters").PARAMETERS for node in (*NODES, VIZ)}
    if not colon:
        return unprefixed_rule_problem(rule, name, tables)
    if prefix not in names:
        return f"-p {rule}: no node is called {prefix!r}: {nearest_hint(prefix, names, 'the nodes')}"
    if not any(spec.name == name for spec in tables[prefix]):
        return f"-p {rule}: the {prefix} has no parameter {name!r}: {unknown_name_hint(name, tables[prefix])}"
    return None


def unprefixed_rule_problem(rule: str, name: str, tables: dict) -> str:
    """Why ``-p rule`` without a node's prefix is refused: the rules to give instead (the new
    names of a renamed parameter), or the nearest name of any node's."""
    value = rule.partition(":=")[2]
    owners = [f"{n}:{name}" for n, table in tables.items() if any(spec.name == name for spec in table)]
    if owners:
        forms = " or ".join(f"-p {owner}:={value}" for owner in owners)
        return f"-p {rule} names no node, and every node would get it: give it as {forms}"
    renamed = [f"{n}:{spec.name}" for n, table in tables.items() if (spec := renamed_to(name, table)) is not None]
    if renamed:
        return f"-p {rule}: {name} was renamed: give it as " + " or ".join(f"-p {r}:={value}" for r in renamed)
    everyone = sorted({spec.name for table in tables.values() for spec in table})
    return f"-p {rule}: no node has a parameter {name!r}: {nearest_hint(name, everyone, 'see mows-graph --help')}"


def ros_arguments_problem(ros_args: list[str]) -> str | None:
    """Why the ROS arguments for every node are refused, or None (``parameter_rule_problem``)."""
    argv = ["mows-graph", "--ros-args", *ros_args]
    if (problem := arguments_problem(argv)) is not None:
        return problem
    rules = ros_argument_values(argv, ("-p", "--param"))
    return next((problem for rule in rules if (problem := parameter_rule_problem(rule)) is not None), None)


# Backends that cannot turn the stage: every orientation is the operator's turn, so the nodes
# whose goals turn the probe must ask for it (orientation manual), or each "angle" would be
# measured at the one angle the probe happens to stand at.
STAGELESS_BACKENDS = ("nidaqmx",)


def start_value(node: str, name: str, ros_args: list[str]):
    """The value ``node`` starts with for parameter ``name``: its parameter file's, then any
    ``--params-file``'s, then ``-p NODE:name:=value`` (the order rcl applies them in)."""
    argv = ["mows-graph", "--ros-args", *ros_args]
    graph_node = next(n for n in NODES if n.name == node)
    value = None
    for path in [graph_node.config_path(), *ros_argument_values(argv, ("--params-file",))]:
        for key, section in (yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}).items():
            if key.rsplit("/", 1)[-1] in (node, "**") and isinstance(section, dict):
                value = (section.get("ros__parameters") or {}).get(name, value)
    override = prefixed_overrides(node, argv, [n.name for n in NODES]).get(name)
    return override.value if override is not None else value


def stage_problem(ros_args: list[str]) -> str | None:
    """Why the graph is refused: a driver backend that cannot turn the stage with a node that
    would turn it (orientation stage); None when every turn is the operator's or the driver's."""
    backend = start_value("driver", "backend", ros_args)
    if backend not in STAGELESS_BACKENDS:
        return None
    turning = [node for node in TURNING_NODES if node not in manual_turns(ros_args)]
    if not turning:
        return None
    give = " ".join(f"-p {node}:orientation:=manual" for node in turning)
    return (
        f"driver backend {backend!r} cannot turn the stage, but the {' and the '.join(turning)} would "
        f"(orientation stage): every orientation would be measured where the probe stands. Give {give}: "
        "each turn is then asked for here and confirmed"
    )


def manual_turns(ros_args: list[str]) -> list[str]:
    """The nodes that will ask the operator to turn the probe by hand (``orientation: manual``)."""
    return [node for node in TURNING_NODES if start_value(node, "orientation", ros_args) == "manual"]
