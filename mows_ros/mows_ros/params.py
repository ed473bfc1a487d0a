"""Node parameters declared from one table and validated whenever they are set.

A node lists its parameters once, as a tuple of ``ParamSpec``; ``declare_parameters`` turns
each row into a ROS parameter with a descriptor (description, range, read-only) that
``ros2 param describe`` shows, and rejects bad values with a reason that names the
parameter, its value and what is allowed. A parameter given to the node (``-p name:=value``
or a parameter file) that the table does not have stops it at start-up with the nearest valid
name (:class:`UnknownParameterError`): rclpy, with ``allow_undeclared_parameters`` off, keeps
such an override unused and silent, and the node would run on its default.
"""

import difflib
from collections.abc import Callable, Sequence
from dataclasses import dataclass

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


def refuse_unknown_overrides(node: Node, table: Sequence[ParamSpec]) -> None:
    """:class:`UnknownParameterError` for the first override of ``node`` that is none of its
    parameters. The overrides (``-p`` and parameter files, after rcl matched the node's name)
    are rclpy's ``Node._parameter_overrides``: rclpy has no public accessor for them."""
    known = [spec.name for spec in table]
    for name in sorted(node._parameter_overrides):
        if name in known or name in ROS_OWN or name.startswith("qos_overrides."):
            continue
        nearest = difflib.get_close_matches(name, known, n=1, cutoff=0.6)
        hint = f"did you mean {nearest[0]}?" if nearest else f"this node's parameters: {', '.join(known)}"
        raise UnknownParameterError(
            f"{node.get_name()}: unknown parameter {name!r} (from -p or a parameter file): {hint}"
        )


def parameter_values(node: Node, table: Sequence[ParamSpec]) -> dict[str, Value]:
    """The current value of every parameter in ``table``."""
    return {spec.name: node.get_parameter(spec.name).value for spec in table}
