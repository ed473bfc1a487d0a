"""The Effect type: a physical effect the published model leaves out, as an edit of the physics.

Every effect edits the per-row :class:`mows.lab.model.configuration.Configuration` (field, gradient,
Hessian, gravity, spring, readout), and the frequency follows from the potential U(θ) of
docs/physics.md §4 with the exact rest angle and harmonic balance, so effects compose and stay
right at mT fields. Every effect is *off* when all its parameters are at their off values (0,
unless a plugin declares another: :attr:`Parameter.off`) and is smooth there (score tests and
refits start from there). Where the size of an effect follows from probe
constants (gravity: a·g·l; static deflection: m, kM and By'), the free parameter is the unknown
geometry or a dimensionless strength with 1 = the physics as predicted; an effect whose size is
known entirely (``physical``) can also be held at it, with no free parameter
(:meth:`Effect.at_physics`, labelled ``name (at physics)``).

The built-in effects are in :mod:`mows.lab.model.catalog`, user plugins are read by
:mod:`mows.lab.model.plugins`; effects join a model with ``FrequencyModel(probe) + effect``
(:mod:`mows.lab.model.frequency_model`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from mows.lab.data.probe_rows import ProbeSet, probe_parts
from mows.lab.data.table import MissingColumnError
from mows.lab.model.configuration import Configuration
from mows.physics.probe import Probe

if TYPE_CHECKING:
    from mows.lab.data.table import MeasurementTable

AT_PHYSICS = " (at physics)"  # label suffix of an effect held at its physical values
# Each parameter's value as physics, the probe file and the table's reference allow it,
# (centre, σ), or None where physics says nothing (a free calibration term such as an
# unreferenced field).
Prior = Callable[[Probe, "MeasurementTable"], tuple[tuple[float, float] | None, ...]]

# Stages: effects are applied in this order, so that e.g. an angle offset turns the probe
# before fields are projected, and the readout comes last.
ORIENTATION, SOURCES, COMPONENTS, MECHANICS, READOUT = range(5)


@dataclasses.dataclass(frozen=True)
class Parameter:
    """A free parameter: value ``off`` (0 unless declared, e.g. a stiffness off at the spring
    the model already has) is "effect off"; ``lower``/``upper`` are physical bounds; ``scale`` a
    typical size (finite-difference step and parameter scaling)."""

    name: str
    unit: str
    lower: float
    upper: float
    scale: float
    description: str = ""
    off: float = 0.0

    def __post_init__(self) -> None:
        if not (self.lower <= self.off <= self.upper and self.lower < self.upper and self.scale > 0):
            raise ValueError(
                f"parameter {self.name}: needs lower ≤ off value ≤ upper, lower < upper and scale > 0 "
                f"(got {self.lower}, {self.off}, {self.upper}, {self.scale})"
            )


@dataclasses.dataclass(frozen=True, eq=False)
class Effect:
    """One physical effect.

    ``apply(config, rows, probe, *values)`` edits the configuration in place (values in the
    order of ``parameters``). ``requires`` names table columns without which the effect cannot
    be tested. ``priority`` breaks ties inside a group of effects the data cannot tell apart
    (smaller first; docs/model_lab.md). ``check`` names an independent measurement that tests
    the effect directly. ``physical`` holds the parameter values at which the effect is the
    physics as predicted from the probe constants and the table (None when its size is not
    known, e.g. gravity's tilt): the effect can then also be tested *at physics*, with no free
    parameter (:meth:`at_physics`). ``prior`` gives each parameter's value as physics and the
    probe file allow it, (centre, σ): a fit that needs a value far outside it is not physics
    (:mod:`mows.lab.diagnosis.plausibility`). ``generic`` marks a free correction that stands for
    several physical causes and has no value of its own (moment scale, field offset, spring
    drift, angle offset): a model that needs one is not called adequate.
    """

    name: str
    explanation: str
    equation: str
    signature: str
    parameters: tuple[Parameter, ...]
    apply: Callable[..., None]
    stage: int = MECHANICS
    requires: tuple[str, ...] = ()
    priority: int = 100
    check: str = ""
    origin: str = "catalog"
    physical: tuple[float, ...] | None = None
    generic: bool = False  # a free correction with no physical value (a calibration term)
    needs: str = ""  # why a table without the ``requires`` columns cannot test it, in words (default: the columns)
    free: Effect | None = None  # of an effect held at physics: the same effect with its parameters free
    prior: Prior | None = None

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def off_values(self) -> np.ndarray:
        """The parameter values at which the effect is absent (fit order)."""
        return np.array([p.off for p in self.parameters], float)

    @property
    def fixed(self) -> bool:
        """True for an effect held at its physical values (no free parameter)."""
        return self.free is not None

    @property
    def label(self) -> str:
        """The name, with the form when the effect is held at physics."""
        return f"{self.name}{AT_PHYSICS}" if self.fixed else self.name

    def at_physics(self) -> Effect:
        """This effect held at its ``physical`` values: same name, no free parameter."""
        if self.fixed:
            return self
        if self.physical is None:
            raise ValueError(f"effect {self.name} has no physical value: its size is not known in advance")
        apply, values = self.apply, self.physical
        return dataclasses.replace(
            self, parameters=(), free=self, apply=lambda config, rows, probe: apply(config, rows, probe, *values)
        )

    def missing_columns(self, table: MeasurementTable) -> tuple[str, ...]:
        return tuple(name for name in self.requires if not table.has(name))

    def __repr__(self) -> str:
        return f"Effect({self.name!r}, parameters={list(self.parameter_names)})"


def untestable_reason(effect_: Effect, table: MeasurementTable, probes: ProbeSet) -> str | None:
    """Why the effect cannot be evaluated on ``table``, in words; None when it can."""
    missing = effect_.missing_columns(table)
    if missing and effect_.needs:
        return effect_.needs
    if missing:
        return f"needs column{'s' if len(missing) > 1 else ''} {', '.join(missing)}"
    row = table.subset(np.arange(1))  # effects read a row's own columns: one row says it
    ((_, _, entry),) = probe_parts(row, probes)  # with its own probe's constants
    try:
        effect_.apply(Configuration.base(row, entry.probe), row, entry.probe, *effect_.off_values)
    except MissingColumnError as error:
        return f"needs column {error.column}"
    return None
