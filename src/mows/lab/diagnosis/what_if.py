"""What-if measurements: the present table joined with a variant of it that a user could measure.

The variants, cheapest first: more angles (half-way between the present orientations), half
the excitation amplitude, the applied field reversed, the applied field doubled, and a
temperature step when the table has temperatures. :mod:`mows.lab.diagnosis.indistinguishable` evaluates a group's
signatures on them to find the measurement that would tell its members apart. A table longer
than ``WHAT_IF_ROWS`` stands in by that many of its rows (whole sweeps spread over it,
:func:`mows.lab.data.table.stratified_rows`): whether two signatures can be told apart is a
question of their patterns in angle, field, amplitude and time, which those rows hold.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mows.lab.data.probe_rows import ProbeSet
from mows.lab.data.table import WRITER_COLUMN, MeasurementTable, stratified_rows
from mows.lab.model.frequency_model import table_start_swing_rad

WHAT_IF_ROWS = 120


@dataclasses.dataclass
class Variant:
    """A what-if measurement: the ``extra`` rows measured after the ``present`` ones."""

    name: str
    description: str
    extra: MeasurementTable
    present: MeasurementTable | None = None

    @property
    def table(self) -> MeasurementTable:
        """The present rows followed by the extra ones, joined on each call (a long table's
        variants are not all held at once)."""
        assert self.present is not None  # variants() gives every variant its present rows
        return self.present.concatenate(self.extra)


def variants(table: MeasurementTable, probes: ProbeSet) -> list[Variant]:
    """What-if variants of ``table``, cheapest first (module docstring)."""
    if len(table) > WHAT_IF_ROWS:
        table = table.subset(stratified_rows(table.sweep_ids, WHAT_IF_ROWS))
    # The variants state their excitation: each row's start swing as the model takes it, as a
    # column of a table the user measured (so that halving it is heard).
    start = np.degrees(table_start_swing_rad(table, probes))
    table = dataclasses.replace(
        table, columns={**{k: v for k, v in table.columns.items() if k != WRITER_COLUMN}, "amplitude_deg": start}
    )
    found = []
    angles = np.unique(np.mod(table.columns["theta0_deg"], 360.0))
    step = float(np.median(np.diff(angles))) if len(angles) > 1 else 90.0
    found.append(
        Variant(
            "more_angles",
            f"measure also half-way between the present orientations (θ0 + {step / 2:g}°)",
            table.with_columns(theta0_deg=table.columns["theta0_deg"] + step / 2),
        )
    )
    found.append(
        Variant(
            "amplitude_halved",
            "repeat the sweep at half the excitation amplitude",
            table.with_columns(amplitude_deg=table.amplitude_deg / 2),
        )
    )
    for name, factor, text in (
        ("field_reversed", -1.0, "repeat with the applied field reversed (coil currents reversed)"),
        ("field_doubled", 2.0, "repeat with twice the applied field"),
    ):
        scaled = {k: v * factor for k, v in table.columns.items() if k.startswith("ref_") or k == "coil_current_a"}
        found.append(Variant(name, text, table.with_columns(**scaled)))
    if table.has("temperature_k"):
        found.append(
            Variant(
                "temperature_step",
                "repeat 5 K warmer (or colder)",
                table.with_columns(temperature_k=table.temperature_k + 5.0),
            )
        )
    return [dataclasses.replace(variant, present=table) for variant in found]
