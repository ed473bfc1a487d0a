"""Node parameters declared from one table and validated whenever they are set.

A node lists its parameters once, as a tuple of ``ParamSpec``; ``declare_parameters`` turns
each row into a ROS parameter with a descriptor (description, range, read-only) that
``ros2 param describe`` shows, and rejects bad values with a reason that names the
parameter, its value and what is allowed. A parameter given to the node (``-p name:=value``
or a parameter file) that the table does not have stops it at start-up with the nearest valid
name (:class:`UnknownParameterError`): rclpy, with ``allow_undeclared_parameters`` off, keeps
such an override unused and silent, and the node would run on its default.

A renamed parameter keeps its old name for one release in its row (``ParamSpec.formerly``):
the old name is refused wherever it is set (``-p``, a parameter file, ``ros2 param set``,
mows-graph) with the new name in the reason (:func:`unknown_name_hint`), never taken silently.
"""

import difflib
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import yaml
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.node import Node
from rclpy.parameter import Parameter

Value = bool | int | float | str
# Parameters rclpy declares on every node itself; qos_overrides.* belong to publishers.
ROS_OWN = ("use_sim_time", "start_type_description_service")


class UnknownParameterError(ValueError):
    """A parameter override the node does not have, with the nearest names it does have."""


@dataclass(frozen=True)
class ParamSpec:
    """One row of a node's parameter table."""

    name: str
    default: Value
    description: str
    range: tuple[float, float] | None = None  # inclusive bounds for numbers
    choices: tuple[str, ...] = ()  # allowed values of a string parameter
    read_only: bool = False
    check: Callable[[Value], str | None] | None = None  # why a value is refused, beyond range and choices
    formerly: tuple[str, ...] = ()  # its names of the previous release: refused, with this name as the hint

    def descriptor(self) -> ParameterDescriptor:
        descriptor = ParameterDescriptor(name=self.name, description=self.description, read_only=self.read_only)
        if self.choices:
            descriptor.additional_constraints = "one of: " + ", ".join(self.choices)
        if self.range is not None:
            low, high = self.range
            if isinstance(self.default, int):
                descriptor.integer_range = [IntegerRange(from_value=low, to_value=high, step=0)]
            else:
                descriptor.floating_point_range = [FloatingPointRange(from_value=low, to_value=high, step=0.0)]
        return descriptor

    def request_problem(self, value: Value, field: str) -> str | None:
        """Why ``value``, asked for in a request's ``field``, is outside this parameter's limits
        (not finite, or out of its range), or None: a request obeys the limits of the node's
        parameters, as ``ros2 param set`` does."""
        if isinstance(value, float) and not math.isfinite(value):
            return f"{field}={value!r} is not finite"
        if self.range is not None and not self.range[0] <= value <= self.range[1]:
            low, high = self.range
            return f"{field}={value!r} is outside [{low:g}, {high:g}] (the limits of the parameter {self.name})"
        return None

    def problem(self, value: Value) -> str | None:
        """Why ``value`` is not allowed for this parameter, or None if it is. (rclpy has
        already refused values outside the descriptor's range, NaN included.)"""
        if self.choices and value not in self.choices:
            return f"{self.name}={value!r} is not one of {', '.join(self.choices)}"
        return self.check(value) if self.check is not None else None


def declare_parameters(node: Node, table: Sequence[ParamSpec]) -> None:
    """Declare every parameter of ``table`` on ``node`` and validate all later sets.

    The check is registered before the declaration so that values from a parameter file
    are validated too: a bad file stops the node at start-up instead of running it wrong.
    """
    specs = {spec.name: spec for spec in table}

    def validate(parameters: list[Parameter]) -> SetParametersResult:
        problems = [
            problem
            for parameter in parameters
            if parameter.name in specs and (problem := specs[parameter.name].problem(parameter.value)) is not None
        ]
        return SetParametersResult(successful=not problems, reason="; ".join(problems))

    node.add_on_set_parameters_callback(validate)
    node.declare_parameters("", [(spec.name, spec.default, spec.descriptor()) for spec in table])
    refuse_unknown_overrides(node, table)


def nearest_hint(name: str, known: Sequence[str], what: str = "this node's parameters") -> str:
    """'did you mean X?' for the known name closest to ``name``, else the list of them."""
    nearest = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
    return f"did you mean {nearest[0]}?" if nearest else f"{what}: {', '.join(known)}"


def renamed_to(name: str, table: Sequence[ParamSpec]) -> ParamSpec | None:
    """The row of ``table`` that was called ``name`` in the previous release, if any."""
    return next((spec for spec in table if name in spec.formerly), None)


def unknown_name_hint(name: str, table: Sequence[ParamSpec]) -> str:
    """What to set instead of ``name``, which ``table`` does not have: its new name when it was
    renamed, else the nearest name (:func:`nearest_hint`)."""
    if (spec := renamed_to(name, table)) is not None:
        return f"renamed {spec.name} ({spec.description}): set {spec.name}"
    return nearest_hint(name, [spec.name for spec in table])


def unknown_parameter(node: Node, name: str, table: Sequence[ParamSpec]) -> str:
    """The refusal of a parameter ``name`` that ``node`` does not have, with what to set instead."""
    return f"{node.get_name()}: unknown parameter {name!r}: {unknown_name_hint(name, table)}"


def refuse_unknown_overrides(node: Node, table: Sequence[ParamSpec]) -> None:
    """:class:`UnknownParameterError` for the first override of ``node`` that is none of its
    parameters. The overrides (``-p`` and parameter files, after rcl matched the node's name)
    are rclpy's ``Node._parameter_overrides``: rclpy has no public accessor for them."""
    known = [spec.name for spec in table]
    for name in sorted(node._parameter_overrides):
        if name in known or name in ROS_OWN or name.startswith("qos_overrides."):
            continue
        raise UnknownParameterError(f"{unknown_parameter(node, name, table)} (from -p or a parameter file)")


def ros_argument_values(argv: Sequence[str], flags: Sequence[str]) -> list[str]:
    """The values that follow any of ``flags`` among the ROS arguments of ``argv`` (``-p``:
    the ``[node:]name:=value`` rules, ``--params-file``: the files)."""
    values, in_ros_args, taking = [], False, False
    for arg in argv:
        if arg == "--ros-args":
            in_ros_args = True
        elif arg == "--":
            in_ros_args = False
        elif in_ros_args and taking:
            values.append(arg)
        taking = in_ros_args and arg in flags
    return values


def params_file_problem(path: str) -> str | None:
    """Why ``path`` is not a ROS parameter file (rcl takes a YAML file of any other shape and
    applies nothing from it), or None."""
    try:
        content = yaml.safe_load(open(path, encoding="utf-8"))
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
        return f"--params-file {path}: {error}"
    nodes_ok = isinstance(content, dict) and content
    if nodes_ok and all(isinstance(v, dict) and isinstance(v.get("ros__parameters"), dict) for v in content.values()):
        return None
    return f"--params-file {path}: not a ROS parameter file (expected NODE: {{ros__parameters: {{name: value}}}})"


def prefixed_overrides(node_name: str, argv: Sequence[str], graph_names: Sequence[str]) -> dict[str, Parameter]:
    """The overrides ``-p NODE:name:=value`` of ``argv`` whose NODE is ``node_name``, by name.

    rcl matches NODE against the node's fully qualified name, so inside a namespace
    (``/probe_a/driver``) it drops ``driver:name:=value`` without a word; the name alone is
    what ``mows-graph`` documents. The value is YAML, as rcl reads it. A NODE that is neither
    this node nor another of ``graph_names`` is refused with the nearest name
    (:class:`UnknownParameterError`): its override would reach no node."""
    overrides = {}
    for rule in ros_argument_values(argv, ("-p", "--param")):
        target, _, text = rule.partition(":=")
        prefix, colon, name = target.rpartition(":")
        if not colon or "/" in prefix:
            continue  # unprefixed, or a fully qualified name that rcl matches itself
        if prefix != node_name:
            if prefix not in graph_names:
                raise UnknownParameterError(
                    f"-p {rule}: no node is called {prefix!r}: {nearest_hint(prefix, graph_names, 'the nodes')}"
                )
            continue
        try:
            overrides[name] = Parameter(name, value=yaml.safe_load(text))
        except (TypeError, ValueError, yaml.YAMLError) as error:
            raise UnknownParameterError(f"-p {rule}: the value is no ROS parameter value ({error})") from None
    return overrides


def spec_named(table: Sequence[ParamSpec], name: str) -> ParamSpec:
    """The row of ``table`` for the parameter ``name``."""
    return next(spec for spec in table if spec.name == name)


def parameter_values(node: Node, table: Sequence[ParamSpec]) -> dict[str, Value]:
    """The current value of every parameter in ``table``."""
    return {spec.name: node.get_parameter(spec.name).value for spec in table}
