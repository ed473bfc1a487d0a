"""A reader's columns made a measurement table (:class:`mows.lab.data.table.MeasurementTable`),
with notes of what was assumed: the project's own tables mended rather than refused, values that
are possible but seldom meant, a missing reference.

Tables the project's tools write (``mows fit --csv``, :func:`tool_table`) carry the column
``mows_table_format`` = 1 in every row. Their ``amplitude_deg`` is an estimate pooled from single
fits, which the lab does not use (the start swing is the stop less the deflection:
docs/model_lab.md, "Start swing"), and a row may hold a fit that did not determine it. Such a
table is never refused for its values: a row whose ``amplitude_deg`` is NaN or ≤ 0 keeps NaN
there, a row with a NaN, infinite or impossible value in another column is left out, and the
notes name those rows. A table without the marker (external) with such values is refused by the
table itself, naming the rows.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from mows.lab.data.table import (
    FIELD,
    GRADIENT,
    RANGED_COLUMNS,
    REQUIRED,
    WRITER_COLUMN,
    MeasurementTable,
    broken_rules,
    rows_outside,
    rows_text,
)
from mows.physics.ranges import RANGES

TABLE_FORMAT = 1.0  # the value of WRITER_COLUMN in every row of our own tables
RADIAN_LOOKING_DEG = 2.0 * np.pi  # angles in degrees all within ±2π: most likely radians

# What a reader notes of the reference (with_notes); joining one (reference.with_reference) drops them.
NO_FIELD = "no reference field: the base model predicts f = f00 at every row"
NO_BZ = "no ref_bz_t: the reference z component is taken as 0 (plane_tilt cannot be tested)"
NO_GRADIENT = "no reference gradient: taken as 0"


def tool_table(columns: Mapping[str, np.ndarray], source: str) -> MeasurementTable:
    """The table of ``columns`` as the project's tools write it: marked with
    ``mows_table_format`` (module docstring), so that the lab reads its ``amplitude_deg`` as
    evidence and mends rather than refuses its rows."""
    n = len(next(iter(columns.values())))
    mended, notes = _mend_own({**columns, WRITER_COLUMN: np.full(n, TABLE_FORMAT)})
    return MeasurementTable(mended, source, notes)


def _mend_own(columns: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], tuple[str, ...]]:
    """(columns, notes) of one of our own tables made valid: impossible start swings set to NaN,
    rows with any other impossible value left out; the notes name the rows. Columns that
    the table refuses for their names or lengths are left to it."""
    if any(name not in columns for name in REQUIRED) or len({len(v) for v in columns.values()}) > 1:
        return columns, ()
    notes = []
    if "amplitude_deg" in columns:
        notes.append(
            "amplitude_deg (pooled from single fits) is not used: the start swing is the stop less the deflection"
        )
        amplitude = columns["amplitude_deg"]
        bad = np.flatnonzero(~(amplitude > 0))
        if bad.size:
            columns = {**columns, "amplitude_deg": np.where(amplitude > 0, amplitude, np.nan)}
            notes.append(f"amplitude_deg is NaN or ≤ 0 in {rows_text(bad)} (a fit that did not determine it)")
    checked = {name: values for name, values in columns.items() if name != "amplitude_deg"}
    broken = {name: rows for name, _, rows in broken_rules(checked)}
    if broken:
        rows = np.unique(np.concatenate(list(broken.values())))
        keep = ~np.isin(np.arange(len(columns["f_hz"])), rows)
        columns = {name: values[keep] for name, values in columns.items()}
        notes.append(f"left out {rows_text(rows)}: NaN, infinite or impossible values in {', '.join(sorted(broken))}")
    return columns, tuple(notes)


def unusual_values(columns: Mapping[str, np.ndarray]) -> list[str]:
    """Notes of values that are possible but seldom meant (:mod:`mows.physics.ranges`): a
    temperature in °C, a duration in ms, angles in radians, times before the start."""
    notes = []
    for name, quantity in RANGED_COLUMNS.items():
        if name in columns:
            bounds = RANGES[quantity]
            odd = rows_outside(columns[name], bounds.usual)
            if odd.size:
                notes.append(
                    f"{name} is unusual in {rows_text(odd)} (usually {bounds.text(bounds.usual)}; {bounds.hint}): "
                    "used as given"
                )
    for name in ("theta0_deg", "amplitude_deg"):
        values = columns.get(name, np.zeros(0))
        values = values[np.isfinite(values)]
        if len(values) > 2 and np.all(np.abs(values) <= RADIAN_LOOKING_DEG):
            notes.append(f"{name} lies within ±{RADIAN_LOOKING_DEG:.2f} in every row: radians given as degrees?")
    if "t_s" in columns and np.any(columns["t_s"] < 0):
        notes.append(f"t_s is negative in {rows_text(np.flatnonzero(columns['t_s'] < 0))}: times before the start?")
    return notes


def with_notes(columns: Mapping[str, np.ndarray], source: str, notes: list[str]) -> MeasurementTable:
    """The table of a reader's ``columns`` with its ``notes`` and those of this module: our own
    tables mended, θ0 wrapped into [0, 360), unusual values and a missing reference noted."""
    if WRITER_COLUMN in columns:
        columns, mended = _mend_own({name: np.asarray(values, float) for name, values in columns.items()})
        notes = list(notes) + list(mended)
    theta = columns.get("theta0_deg", np.zeros(0))
    wrapped = np.flatnonzero((theta < 0.0) | (theta >= 360.0))
    if wrapped.size:
        first = theta[wrapped[0]]
        notes.append(
            f"theta0_deg outside [0, 360) in {rows_text(wrapped)}: read as the same orientation modulo "
            f"360 (e.g. {first:g}° is {first % 360.0:g}°)"
        )
    notes += unusual_values(columns)
    if not any(name in columns for name in FIELD):
        notes.append(NO_FIELD)
    elif "ref_bz_t" not in columns and "ref_bx_t" in columns:
        notes.append(NO_BZ)
    if not any(name in columns for name in GRADIENT):
        notes.append(NO_GRADIENT)
    return MeasurementTable(columns, source, tuple(notes))
