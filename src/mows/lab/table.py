"""Measurement tables: one row per ring-down result, from CSV or from a rosbag2 bag.

Frame (the lab's contract with the user): the rotation plane is the global x–y plane, θ0 is
counted from +x towards +y, z completes a right-handed frame. The probe frame of a row is
x' = (cos θ0, sin θ0, 0), y' = (−sin θ0, cos θ0, 0), z' = z (docs/architecture.md).

Columns (CSV header names, SI units but for the ``*_deg`` columns):

=====================================  =========  ===================================================
``theta0_deg``, ``f_hz``, ``f_std_hz``  required   orientation, ring-down frequency and its std. uncertainty
``t_s``, ``sweep``                      optional   time; sweep number (leave-one-sweep-out CV)
``ref_bx_t``, ``ref_by_t``, ``ref_bz_t``  optional   reference field at the probe, global frame
``ref_gxx_t_per_m``, ``ref_gxy_t_per_m``,  optional   in-plane reference gradient G_ij = ∂B_i/∂x_j
``ref_gyy_t_per_m``
``coil_current_a``, ``amplitude_deg``,  optional   covariates used by effects (``amplitude_deg`` is the
``temperature_k``, ``damping_per_s``,              fitted θmax at the start of the ring-down; the
``duration_s``                                     last two as in ``RingdownFit``)
any other numeric column                optional   kept as a covariate for the diagnostics
=====================================  =========  ===================================================

The unmeasured gradient components are completed by Maxwell's equations for a field that is
static and source-free at the probe: Gxz = Gyz = 0 (unknown, taken as zero: they do not act
on a lever that swings in the plane) and Gzz = −(Gxx + Gyy) (∇·B = 0).
"""
from __future__ import annotations

import csv
import dataclasses
import math
import pathlib
from typing import Mapping

import numpy as np

from mows.records import stamps
from mows.physics.pose import probe_axes

REQUIRED = ("theta0_deg", "f_hz", "f_std_hz")
FIELD = ("ref_bx_t", "ref_by_t", "ref_bz_t")
GRADIENT = ("ref_gxx_t_per_m", "ref_gxy_t_per_m", "ref_gyy_t_per_m")
KNOWN = REQUIRED + ("t_s", "sweep") + FIELD + GRADIENT + (
    "coil_current_a", "amplitude_deg", "temperature_k", "damping_per_s", "duration_s")

POSITIVE = ("f_hz", "f_std_hz", "amplitude_deg", "duration_s", "temperature_k")
NOT_COVARIATES = {"theta0_deg", "f_hz", "f_std_hz", "sweep", "ref_bx_t", "ref_by_t"}

RINGDOWN_TOPIC = "/mows/ringdown"
SWEEP_TOPIC = "/mows/sweep"


class TableError(ValueError):
    """A measurement table that cannot be used, with the column and rows at fault."""


class MissingColumnError(AttributeError, KeyError):
    """An effect or plugin asked for a column the table does not have."""

    def __init__(self, column: str):
        super().__init__(column)
        self.column = column

    def __str__(self):
        return f"the table has no column '{self.column}'"


def _rows_text(rows) -> str:
    rows = [int(r) + 1 for r in rows]
    shown = ", ".join(str(r) for r in rows[:8])
    return f"row{'s' if len(rows) > 1 else ''} {shown}{' …' if len(rows) > 8 else ''} (data rows, 1-based)"


@dataclasses.dataclass(frozen=True, eq=False)
class MeasurementTable:
    """A validated table of ring-down results (see the module docstring for the columns).

    Columns are available as attributes (``table.coil_current_a``): that is how effects and
    plugins read them. ``notes`` records what was assumed while reading.
    """

    columns: Mapping[str, np.ndarray]
    source: str = "table"
    notes: tuple = ()

    def __post_init__(self):
        columns = {name: np.asarray(values, float) for name, values in self.columns.items()}
        object.__setattr__(self, "columns", columns)
        _validate(columns)

    # --- plain columns --------------------------------------------------------------------
    def __getattr__(self, name):
        columns = self.__dict__.get("columns", {})
        if name in columns:
            return columns[name]
        raise MissingColumnError(name)

    def has(self, name: str) -> bool:
        return name in self.columns

    def __len__(self) -> int:
        return len(self.columns["f_hz"])

    @property
    def n(self) -> int:
        return len(self)

    @property
    def theta0_rad(self) -> np.ndarray:
        return np.radians(self.columns["theta0_deg"])

    @property
    def sweep_ids(self) -> np.ndarray:
        """Integer sweep of each row (all 0 without a ``sweep`` column)."""
        return self.columns["sweep"].astype(int) if self.has("sweep") else np.zeros(len(self), int)

    @property
    def amplitude_rad(self):
        return np.radians(self.columns["amplitude_deg"]) if self.has("amplitude_deg") else None

    # --- reference field in the global frame ------------------------------------------------
    @property
    def field_t(self) -> np.ndarray:
        """Reference field (n, 3), global frame; zero where the table has none."""
        return np.stack([self.columns.get(name, np.zeros(len(self))) for name in FIELD], -1)

    @property
    def gradient_t_per_m(self) -> np.ndarray:
        """Reference gradient tensor (n, 3, 3), completed by Maxwell (module docstring)."""
        gxx, gxy, gyy = (self.columns.get(name, np.zeros(len(self))) for name in GRADIENT)
        g = np.zeros((len(self), 3, 3))
        g[:, 0, 0], g[:, 0, 1], g[:, 1, 0], g[:, 1, 1] = gxx, gxy, gxy, gyy
        g[:, 2, 2] = -(gxx + gyy)
        return g

    def probe_axes(self) -> np.ndarray:
        """Rows x', y', z' of each measurement as (n, 3, 3): ``axes @ v`` is v in the probe frame."""
        return probe_axes(self.theta0_rad)

    @property
    def probe_field_t(self) -> np.ndarray:
        """Reference field (n, 3) in the probe frame: Bx' along the axis, By' = B⊥ across it."""
        return np.einsum("nij,nj->ni", self.probe_axes(), self.field_t)

    # --- diagnostics --------------------------------------------------------------------------
    def covariates(self) -> dict:
        """Every quantity a residual may follow, by name: the table's numeric columns (time,
        current, amplitude, temperature, reference z, extras) and the reference's |B|, B⊥ = By',
        Bx' and G = Gx'x'. Constant ones are left out (a constant is absorbed by f00)."""
        found = {name: values for name, values in self.columns.items() if name not in NOT_COVARIATES}
        if any(self.has(name) for name in FIELD):
            field = self.probe_field_t
            found.update(b_abs_t=np.linalg.norm(self.field_t, axis=-1), b_perp_t=field[:, 1], b_along_t=field[:, 0])
        if any(self.has(name) for name in GRADIENT):
            axes = self.probe_axes()
            found["g_t_per_m"] = np.einsum("ni,nij,nj->n", axes[:, 0], self.gradient_t_per_m, axes[:, 0])
        return {name: values for name, values in found.items() if np.ptp(values) > 0}

    # --- derived tables ---------------------------------------------------------------------
    def subset(self, rows) -> "MeasurementTable":
        """The table restricted to ``rows`` (a boolean mask or indices)."""
        return dataclasses.replace(self, columns={k: v[rows] for k, v in self.columns.items()})

    def with_columns(self, **columns) -> "MeasurementTable":
        """A copy with columns replaced or added (arrays of length n)."""
        return dataclasses.replace(self, columns={**self.columns, **columns})

    def concatenate(self, other: "MeasurementTable") -> "MeasurementTable":
        """Rows of both tables; they must have the same columns."""
        if set(self.columns) != set(other.columns):
            raise TableError(f"cannot join tables with columns {sorted(self.columns)} and {sorted(other.columns)}")
        return dataclasses.replace(self, columns={k: np.concatenate([v, other.columns[k]])
                                                  for k, v in self.columns.items()})

    def to_csv(self, path) -> None:
        names = list(self.columns)
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(names)
            for row in zip(*(self.columns[name] for name in names)):
                writer.writerow([repr(float(v)) for v in row])


def _validate(columns: dict) -> None:
    missing = [name for name in REQUIRED if name not in columns]
    if missing:
        raise TableError(f"missing required column{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
                         f"(required: {', '.join(REQUIRED)})")
    lengths = {name: len(values) for name, values in columns.items()}
    if len(set(lengths.values())) > 1:
        raise TableError(f"columns have different lengths: {lengths}")
    if lengths["f_hz"] == 0:
        raise TableError("the table has no rows")
    for name, rule, rows in _broken_rules(columns):
        raise TableError(f"column '{name}' {rule} in {_rows_text(rows)}")
    for group in (FIELD[:2], GRADIENT):
        given = [name for name in group if name in columns]
        if given and len(given) != len(group):
            raise TableError(f"column{'s' if len(given) > 1 else ''} {', '.join(given)} given without "
                             f"{', '.join(sorted(set(group) - set(given)))}: give all of {', '.join(group)}")
    if "sweep" in columns and np.any(columns["sweep"] != np.round(columns["sweep"])):
        raise TableError(f"column 'sweep' must hold integers: not so in "
                         f"{_rows_text(np.flatnonzero(columns['sweep'] != np.round(columns['sweep'])))}")


def _broken_rules(columns: dict):
    """(column, rule, rows) for the values no column may hold: NaN or ±inf anywhere, and
    values ≤ 0 in the columns that are positive by nature."""
    for name, values in columns.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            yield name, "has NaN or infinite values", bad
    for name in POSITIVE:
        if name in columns:
            bad = np.flatnonzero(columns[name] <= 0)
            if bad.size:
                yield name, "must be > 0: not so", bad


# --- CSV ------------------------------------------------------------------------------------
def read_csv(path, drop_invalid: bool = False) -> MeasurementTable:
    """Read a measurement table from CSV (header row, one row per ring-down).

    Known columns must be numeric in every row; other columns are kept as covariates when all
    their cells are numbers and ignored (with a note) otherwise. With ``drop_invalid`` rows
    with empty, non-numeric, NaN or non-positive values in known columns are dropped and listed
    in ``notes`` instead of raising :class:`TableError`.
    """
    path = pathlib.Path(path)
    try:
        with open(path, newline="") as handle:
            rows = list(csv.reader(handle))
    except OSError as error:
        raise TableError(f"cannot read {path}: {error.strerror}") from None
    rows = [row for row in rows if any(cell.strip() for cell in row)]
    if not rows:
        raise TableError(f"{path} is empty: expected a header row and data rows")
    header = [name.strip() for name in rows[0]]
    duplicated = sorted({name for name in header if header.count(name) > 1})
    if duplicated:
        raise TableError(f"{path}: column{'s' if len(duplicated) > 1 else ''} {', '.join(duplicated)} appear twice")
    body = rows[1:]
    if not body:
        raise TableError(f"{path}: the table has no rows (only a header)")
    short = [i for i, row in enumerate(body) if len(row) != len(header)]
    if short:
        raise TableError(f"{path}: {_rows_text(short)} do not have {len(header)} cells like the header")
    columns, notes, invalid = {}, [], {}
    for j, name in enumerate(header):
        values = np.array([_number(row[j]) for row in body])
        if name not in KNOWN:  # a covariate is kept only where every row holds a number
            unusable = np.flatnonzero(~np.isfinite(values))
            if unusable.size:
                notes.append(f"column '{name}' is not a finite number in {_rows_text(unusable)}: ignored")
                continue
        bad = np.flatnonzero(np.isnan(values) & np.array([row[j].strip().lower() != "nan" for row in body]))
        if bad.size:
            if not drop_invalid:
                raise TableError(f"{path}: column '{name}': {body[bad[0]][j]!r} is not a number "
                                 f"({_rows_text(bad)})")
            invalid.setdefault(name, set()).update(bad.tolist())
        columns[name] = values
    table_source = str(path)
    if drop_invalid:
        columns, dropped = _drop_invalid_rows(columns, invalid)
        if dropped:
            notes.append(f"dropped {_rows_text(dropped)}: empty, non-numeric, NaN or non-positive values")
    return _with_notes(columns, table_source, notes)


def _number(cell: str) -> float:
    try:
        return float(cell)
    except ValueError:
        return math.nan


def _drop_invalid_rows(columns, invalid):
    bad = set().union(*invalid.values()) if invalid else set()
    for _, _, rows in _broken_rules(columns):
        bad |= set(rows.tolist())
    keep = np.setdiff1d(np.arange(len(next(iter(columns.values())))), sorted(bad))
    return {k: v[keep] for k, v in columns.items()}, sorted(bad)


def _with_notes(columns, source, notes) -> MeasurementTable:
    if not any(name in columns for name in FIELD):
        notes.append("no reference field: the base model predicts f = f00 at every row")
    elif "ref_bz_t" not in columns and "ref_bx_t" in columns:
        notes.append("no ref_bz_t: the reference z component is taken as 0 (plane_tilt cannot be tested)")
    if not any(name in columns for name in GRADIENT):
        notes.append("no reference gradient: taken as 0")
    return MeasurementTable(columns, source, tuple(notes))


def load_table(source, drop_invalid: bool = False, **bag_options) -> MeasurementTable:
    """A :class:`MeasurementTable` from a CSV file, a rosbag2 bag directory (or .mcap file),
    or a mapping of column arrays."""
    if isinstance(source, MeasurementTable):
        return source
    if isinstance(source, Mapping):
        return MeasurementTable({k: np.asarray(v, float) for k, v in source.items()}, "columns")
    if is_bag(source):
        return from_bag(pathlib.Path(source), **bag_options)
    return read_csv(source, drop_invalid=drop_invalid)


def is_bag(source) -> bool:
    """A rosbag2 bag: a directory or an .mcap file."""
    path = pathlib.Path(source)
    return path.is_dir() or path.suffix == ".mcap"


# --- bags -----------------------------------------------------------------------------------
def _stamp_s(message, timestamp_ns) -> float:
    seconds = stamps.seconds(message.header.stamp)
    return seconds if seconds > 0 else 1e-9 * timestamp_ns


def from_bag(path, reference=None, magnet_position_m=(0.0, 0.0, 0.0), ringdown_topic: str = RINGDOWN_TOPIC,
             sweep_topic: str = SWEEP_TOPIC) -> MeasurementTable:
    """A table from the project's bags: ``mows_msgs/msg/RingdownFit`` messages on
    ``ringdown_topic`` (only STATUS_OK fits; the others are counted in ``notes``).

    ``reference`` gives the reference field at the probe:

    - ``None``: no reference columns;
    - a topic name (``"/reference/magnetic_field"``): ``sensor_msgs/msg/MagneticField``
      messages, the one nearest in time to each ring-down (header stamps, global frame);
    - a :class:`mows.physics.field.FieldSource`, its YAML mapping, or a YAML file holding one: the
      exact field and in-plane gradient at ``magnet_position_m``;
    - a simulator scenario (:class:`mows.sim.scenario.Scenario`, a shipped name or a YAML file):
      its sources at its magnet position (:func:`reference_at`).

    Rows are numbered into sweeps by the ``SweepDecomposition`` stamps on ``sweep_topic`` when
    the bag has them (a sweep's stamp is that of its last ring-down).
    """
    from mows.device import bags

    path = pathlib.Path(path)
    if not path.exists():
        raise TableError(f"no bag at {path}")
    topics = [ringdown_topic, sweep_topic] + ([reference] if isinstance(reference, str) and
                                              reference.startswith("/") else [])
    fits, sweeps, fields, failed = [], [], [], 0
    for item in bags.read_bag(path, topics=topics):
        if item.topic == ringdown_topic:
            if getattr(item.message, "tuning", False):
                continue
            if item.message.status == 0:
                fits.append((_stamp_s(item.message, item.timestamp_ns), item.message))
            else:
                failed += 1
        elif item.topic == sweep_topic:
            sweeps.append(_stamp_s(item.message, item.timestamp_ns))
        else:
            vector = item.message.magnetic_field
            fields.append((_stamp_s(item.message, item.timestamp_ns), (vector.x, vector.y, vector.z)))
    if not fits:
        raise TableError(f"{path}: no successful RingdownFit messages on {ringdown_topic}"
                         + (f" ({failed} failed fits)" if failed else ""))
    fits.sort(key=lambda item: item[0])
    stamps = np.array([stamp for stamp, _ in fits])
    columns = {
        "theta0_deg": np.degrees([m.theta0_rad for _, m in fits]),
        "f_hz": np.array([m.frequency_hz for _, m in fits]),
        "f_std_hz": np.array([m.frequency_std_hz for _, m in fits]),
        "t_s": stamps - stamps[0],
        "amplitude_deg": np.degrees([m.amplitude_rad for _, m in fits]),
        "damping_per_s": np.array([m.damping_per_s for _, m in fits]),
        "duration_s": np.array([m.duration_s for _, m in fits]),
        "snr_db": np.array([m.snr_db for _, m in fits]),
    }
    notes = [f"skipped {failed} RingdownFit messages whose status is not OK"] if failed else []
    if sweeps:
        columns["sweep"] = np.searchsorted(np.sort(sweeps), stamps - 1e-9).astype(float)
    columns.update(_reference_columns(reference, stamps, fields, magnet_position_m, path))
    return _with_notes(columns, str(path), notes)


def _reference_columns(reference, stamps, fields, magnet_position_m, path) -> dict:
    if reference is None:
        return {}
    if isinstance(reference, str) and reference.startswith("/"):
        if not fields:
            raise TableError(f"{path}: no sensor_msgs/msg/MagneticField messages on {reference}")
        times = np.array([t for t, _ in fields])
        values = np.array([v for _, v in fields])
        nearest = np.abs(stamps[:, None] - times[None, :]).argmin(axis=1)
        return dict(zip(FIELD, values[nearest].T))
    return reference_columns(reference, len(stamps), magnet_position_m)


def from_sweep(record, reference, probe, decomposition=None) -> MeasurementTable:
    """The table of one rotation sweep (:class:`mows.sweep.record.SweepRecord`) in a static
    ``reference`` (anything :func:`reference_at` takes). With a first-principles
    ``decomposition`` of the sweep, each ring-down's start swing is stop − |θs| at its field
    (:meth:`~mows.sweep.record.SweepRecord.start_amplitudes_rad`); else the pooled stop amplitude."""
    starts = (record.start_amplitudes_rad(decomposition, probe)
              if decomposition is not None and decomposition.ok and decomposition.model == "first_principles"
              else None)
    columns = record.table_columns(starts)
    columns.update(reference_columns(reference, len(record.points)))
    return MeasurementTable(columns, "sweep")


def reference_columns(reference, n: int, magnet_position_m=(0.0, 0.0, 0.0)) -> dict:
    """The reference columns (field, in-plane gradient) of ``n`` rows in a static reference
    (anything :func:`reference_at` takes)."""
    field, gradient = reference_at(reference, magnet_position_m)
    columns = {name: np.full(n, value) for name, value in zip(FIELD, field)}
    columns.update({name: np.full(n, gradient[i, j]) for name, (i, j) in zip(GRADIENT, ((0, 0), (0, 1), (1, 1)))})
    return columns


def reference_at(reference, magnet_position_m=(0.0, 0.0, 0.0)):
    """Field (3,) and gradient (3, 3) at the probe of a reference: a field source (object, YAML
    mapping with a ``type``, or a file holding one) or a simulator scenario (object, name or
    YAML file: its environment's sources at its pose's magnet position)."""
    from mows.physics import field as fields

    point = np.asarray(magnet_position_m, float)
    if isinstance(reference, (str, pathlib.Path)):
        import yaml

        path = pathlib.Path(reference)
        data = yaml.safe_load(path.read_text()) if path.is_file() else None
        if not (isinstance(data, Mapping) and "type" in data):
            from mows.sim.scenario import load_scenario

            reference = load_scenario(str(reference))
        else:
            reference = data
    if isinstance(reference, Mapping):
        reference = fields.source_from_dict(dict(reference))
    if hasattr(reference, "environment"):  # a scenario
        point = np.asarray(reference.pose.magnet_position_m, float)
        reference = reference.environment.source
    return reference.field_t(point), reference.gradient_t_per_m(point)
