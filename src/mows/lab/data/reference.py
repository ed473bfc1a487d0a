"""The reference field of a static source at the probe, as table columns.

A reference is named in one of four ways, and each is turned into one thing, a
:class:`mows.physics.field.FieldSource` and the point where the probe sits
(:func:`reference_source`):

- a field source object, at ``magnet_position_m``;
- a simulator scenario (:class:`mows.sim.scenario.Scenario`): its environment's sources at its
  pose's magnet position;
- a field-source mapping (YAML form, with a ``type`` key), at ``magnet_position_m``;
- a path or name: a YAML file holding a field-source mapping, else a scenario (a shipped
  scenario's name or a scenario YAML file).
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
from collections.abc import Mapping
from typing import Any

import numpy as np

from mows.lab.data.intake import NO_BZ, NO_FIELD, NO_GRADIENT
from mows.lab.data.table import (
    CURVATURE,
    CURVATURE_SPREAD,
    FIELD,
    GRADIENT,
    MeasurementTable,
    TableError,
)
from mows.physics.field import FieldSource, source_from_dict
from mows.physics.schema import Vector, load_yaml
from mows.sim.scenario import Scenario, load_scenario

# The four ways of naming a reference (module docstring).
Reference = FieldSource | Scenario | Mapping[str, Any] | str | os.PathLike[str]
# How far a probe's magnet may sit from the position stated with a field-source reference: set by
# hand at a coil's centre, a few millimetres. What the reference's curvature may be is its value
# at the stated point give or take its change over this distance.
PLACEMENT_M = 5e-3


def reference_columns(
    reference: Reference, n: int, magnet_position_m: Vector = (0.0, 0.0, 0.0)
) -> dict[str, np.ndarray]:
    """The reference columns (field, in-plane gradient) of ``n`` rows in a static reference
    (anything :func:`reference_source` takes)."""
    field, gradient = reference_at(reference, magnet_position_m)
    columns = {name: np.full(n, value) for name, value in zip(FIELD, field)}
    columns.update({name: np.full(n, gradient[i, j]) for name, (i, j) in zip(GRADIENT, ((0, 0), (0, 1), (1, 1)))})
    return columns


def with_reference(
    table: MeasurementTable, reference: Reference, magnet_position_m: Vector = (0.0, 0.0, 0.0)
) -> MeasurementTable:
    """``table`` with the reference columns of a static ``reference`` (a CSV that ``mows fit``
    wrote has none); TableError when the table already has reference columns of its own."""
    own = [name for name in (*FIELD, *GRADIENT) if table.has(name)]
    if own:
        raise TableError(f"{table.source} already has reference columns ({', '.join(own)}): give no --reference")
    columns = reference_columns(reference, len(table), magnet_position_m)
    joined = table.with_columns(**columns, **curvature_columns(reference, len(table), magnet_position_m))
    notes = tuple(note for note in table.notes if note not in (NO_FIELD, NO_BZ, NO_GRADIENT))
    return dataclasses.replace(joined, notes=notes + (f"reference: {reference} (static, at the probe)",))


def curvature_columns(
    reference: Reference, n: int, magnet_position_m: Vector = (0.0, 0.0, 0.0)
) -> dict[str, np.ndarray]:
    """The curvature columns of ``n`` rows in a static field-source reference: the in-plane
    components of its Hessian at the probe (CURVATURE), and the most any of them changes when the
    probe is moved by PLACEMENT_M along x, y or z (CURVATURE_SPREAD): what the reference's
    sources can make there (:mod:`mows.lab.diagnosis.plausibility`)."""
    source, point = reference_source(reference, magnet_position_m)
    index = ((0, 0, 0), (0, 0, 1), (0, 1, 1), (1, 1, 1))

    def in_plane(at: np.ndarray) -> np.ndarray:
        hessian = source.hessian_t_per_m2(at)
        return np.array([hessian[i] for i in index])

    centre = in_plane(point)
    moved = [in_plane(point + sign * PLACEMENT_M * axis) for axis in np.eye(3) for sign in (-1.0, 1.0)]
    spread = float(np.max(np.abs(np.array(moved) - centre)))
    columns = {name: np.full(n, value) for name, value in zip(CURVATURE, centre)}
    return columns | {CURVATURE_SPREAD: np.full(n, spread)}


def reference_at(reference: Reference, magnet_position_m: Vector = (0.0, 0.0, 0.0)) -> tuple[np.ndarray, np.ndarray]:
    """Field (3,) and gradient (3, 3) at the probe of a reference (module docstring)."""
    source, point = reference_source(reference, magnet_position_m)
    return source.field_t(point), source.gradient_t_per_m(point)


def swept_reference_at(source: FieldSource, magnet_position_m: Vector, lever_m: float) -> tuple[np.ndarray, np.ndarray]:
    """What a rotation sweep in the x–y plane determines of ``source`` at a magnet on a lever of
    ``lever_m``: the field (3,) plus (l²/4)·∂²B/∂z², and the gradient (3, 3), at the magnet's rest
    position. The trace part of the field's curvature over the lever's arc turns with θ0 as the
    field does, so no sweep tells the two apart (docs/multi_probe.md)."""
    point = np.asarray(magnet_position_m, float)
    curvature = source.hessian_t_per_m2(point)[:, 2, 2]
    return source.field_t(point) + lever_m**2 / 4.0 * curvature, source.gradient_t_per_m(point)


def reference_source(
    reference: Reference, magnet_position_m: Vector = (0.0, 0.0, 0.0)
) -> tuple[FieldSource, np.ndarray]:
    """(field source, probe point (3,)) of a reference named in any of the module's four ways."""
    if isinstance(reference, (str, os.PathLike)):
        reference = _read(reference)
    if isinstance(reference, Scenario):
        return reference.environment.source, np.asarray(reference.pose.magnet_position_m, float)
    if isinstance(reference, Mapping):
        reference = source_from_dict(dict(reference))
    if not isinstance(reference, FieldSource):
        raise TypeError(
            f"a reference is a field source, a scenario, a field-source mapping or a file or name "
            f"of one; got {type(reference).__name__}"
        )
    return reference, np.asarray(magnet_position_m, float)


def _read(name: str | os.PathLike[str]) -> FieldSource | Scenario:
    """The field source of a YAML file that holds one, else the scenario so named (a YAML file or
    a shipped scenario's name); the file read once."""
    path = pathlib.Path(name)
    if not path.is_file() and path.suffix not in (".yaml", ".yml"):
        return load_scenario(str(name))  # a shipped scenario's name
    return load_yaml(path, "reference", lambda data: _source_or_scenario(data, path.parent))


def _source_or_scenario(data: Any, base_dir: pathlib.Path) -> FieldSource | Scenario:
    if isinstance(data, Mapping) and "type" in data:
        return source_from_dict(dict(data))
    return Scenario.from_dict(data, base_dir=base_dir)
