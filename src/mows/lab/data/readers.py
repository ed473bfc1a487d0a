"""Reading measurement tables: CSV files, the project's rosbag2 bags and rotation sweeps.

Each reader gathers the columns of :mod:`mows.lab.data.table` and hands them to
:func:`mows.lab.data.intake.with_notes`, which validates them and notes what was assumed. Reference
fields of static sources come from :mod:`mows.lab.data.reference`.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import os
import pathlib
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from mows.device.recording import bags
from mows.estimate.ringdown import FitStatus
from mows.lab.data.intake import with_notes
from mows.lab.data.reference import Reference, reference_columns
from mows.lab.data.table import FIELD, KNOWN, PROBE, MeasurementTable, TableError, broken_rules, rows_text
from mows.physics.probe import PAPER_PROBE, Probe
from mows.physics.schema import Vector
from mows.records import stamps
from mows.records.files import read_input
from mows.sweep.decomposition import Decomposition
from mows.sweep.probes import f00_of
from mows.sweep.record import SweepPoint, SweepRecord

RINGDOWN_TOPIC = "/mows/ringdown"
SWEEP_TOPIC = "/mows/sweep"


def read_csv(path: str | os.PathLike[str], drop_invalid: bool = False) -> MeasurementTable:
    """Read a measurement table from CSV (header row, one row per ring-down).

    Known columns must be numeric in every row; other columns are kept as covariates when all
    their cells are numbers and ignored (with a note) otherwise. With ``drop_invalid`` rows
    with empty, non-numeric, NaN or non-positive values in known columns are dropped and listed
    in ``notes`` instead of raising :class:`TableError`.
    """
    path = read_input(path)
    numeric = _read_numeric(path)
    if numeric is not None:
        columns, notes = numeric, []
        if drop_invalid:  # every cell is a finite number: only non-positive values can be invalid
            columns, dropped = _drop_invalid_rows(columns, {})
            notes = [f"dropped {rows_text(dropped)}: non-positive values"] if dropped else []
        return with_notes(columns, str(path), notes)
    return _read_cells(path, drop_invalid)


def _read_numeric(path: pathlib.Path) -> dict[str, np.ndarray] | None:
    """The columns of a CSV whose every data cell is a finite number, parsed by numpy's C
    reader (a 500 000-row table in seconds, its values only in memory); None for any other
    file, which :func:`_read_cells` then reads cell by cell to name what is wrong."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:
            header = [name.strip() for name in next(csv.reader([handle.readline()]), [])]
            if not all(header) or len(set(header)) != len(header):
                return None
            with warnings.catch_warnings():  # a header without rows: said by _read_cells
                warnings.simplefilter("ignore", UserWarning)
                values = np.loadtxt(handle, delimiter=",", comments=None, quotechar='"', ndmin=2)
    except (OSError, ValueError, csv.Error):  # a cell that is no number, a short row, not UTF-8, too long
        return None
    if values.shape != (len(values), len(header)) or not len(values) or not np.isfinite(values).all():
        return None
    return {name: np.ascontiguousarray(column) for name, column in zip(header, values.T)}


def _read_cells(path: pathlib.Path, drop_invalid: bool) -> MeasurementTable:
    """:func:`read_csv` cell by cell: every problem named by column and row."""
    try:
        with open(path, newline="", encoding="utf-8-sig") as handle:  # -sig: Excel's byte-order mark
            reader = csv.reader(handle)
            rows = list(reader)
    except OSError as error:
        raise TableError(f"cannot read {path}: {error.strerror}") from None
    except csv.Error as error:  # a cell beyond the csv module's field limit (128 KiB): no number
        raise TableError(f"{path}: line {reader.line_num}: {error}: not a table of numbers") from None
    rows = [row for row in rows if any(cell.strip() for cell in row)]
    if not rows:
        raise TableError(f"{path} is empty: expected a header row and data rows")
    header = [name.strip() for name in rows[0]]
    if len(header) == 1 and (separator := next((c for c in ";\t|" if c in header[0]), None)):
        raise TableError(
            f"{path}: the header is one cell, {header[0]!r}: columns are separated by commas, and this "
            f"file looks separated by {separator!r} (save it as comma-separated CSV)"
        )
    duplicated = sorted({name for name in header if header.count(name) > 1})
    if duplicated:
        raise TableError(f"{path}: column{'s' if len(duplicated) > 1 else ''} {', '.join(duplicated)} appear twice")
    body = rows[1:]
    if not body:
        raise TableError(f"{path}: the table has no rows (only a header)")
    short = [i for i, row in enumerate(body) if len(row) != len(header)]
    if short:
        raise TableError(f"{path}: {rows_text(short)} do not have {len(header)} cells like the header")
    columns: dict[str, np.ndarray] = {}
    notes: list[str] = []
    invalid: dict[str, set[int]] = {}  # column → rows that are not numbers
    for j, name in enumerate(header):
        values = np.array([_number(row[j]) for row in body])
        if name not in KNOWN:  # a covariate is kept only where every row holds a number
            unusable = np.flatnonzero(~np.isfinite(values))
            if unusable.size:
                notes.append(f"column '{name}' is not a finite number in {rows_text(unusable)}: ignored")
                continue
        bad = np.flatnonzero(np.isnan(values) & np.array([row[j].strip().lower() != "nan" for row in body]))
        if bad.size:
            if not drop_invalid:
                raise TableError(f"{path}: column '{name}': {body[bad[0]][j]!r} is not a number ({rows_text(bad)})")
            invalid.setdefault(name, set()).update(bad.tolist())
        columns[name] = values
    table_source = str(path)
    if drop_invalid:
        columns, dropped = _drop_invalid_rows(columns, invalid)
        if dropped:
            notes.append(f"dropped {rows_text(dropped)}: empty, non-numeric, NaN or non-positive values")
    return with_notes(columns, table_source, notes)


def _number(cell: str) -> float:
    try:
        return float(cell)
    except ValueError:
        return math.nan


def _drop_invalid_rows(
    columns: dict[str, np.ndarray], invalid: Mapping[str, set[int]]
) -> tuple[dict[str, np.ndarray], list[int]]:
    bad: set[int] = set().union(*invalid.values()) if invalid else set()
    for _, _, rows in broken_rules(columns):
        bad |= set(rows.tolist())
    keep = np.setdiff1d(np.arange(len(next(iter(columns.values())))), sorted(bad))
    return {k: v[keep] for k, v in columns.items()}, sorted(bad)


def logged_at(path: str | os.PathLike[str], times_s: np.ndarray, column: str = "temperature_k") -> np.ndarray:
    """``column`` of a logger's CSV (a header with ``t_s``, on the device clock of the bag's
    stamps, and ``column``) at ``times_s``, interpolated linearly between its samples;
    ValueError naming what is wrong: a missing column, a cell that is no finite number, times
    that do not increase, or ``times_s`` outside the log's span (never extrapolated)."""
    path = read_input(path)
    with open(path, newline="", encoding="utf-8-sig") as handle:
        rows = list(csv.DictReader(handle))
    if not rows or not {"t_s", column} <= set(rows[0]):
        raise ValueError(f"a log of t_s and {column} needs both columns in its header")
    try:
        times, values = (np.array([float(row[name]) for row in rows]) for name in ("t_s", column))
    except (TypeError, ValueError):
        raise ValueError(f"every t_s and {column} of the log must be a number") from None
    if not (np.isfinite(times).all() and np.isfinite(values).all() and np.all(np.diff(times) > 0)):
        raise ValueError(f"the log's t_s must increase and its t_s and {column} be finite numbers")
    outside = np.flatnonzero((times_s < times[0]) | (times_s > times[-1]))
    if outside.size:
        raise ValueError(
            f"the log spans t_s {times[0]:.6g} … {times[-1]:.6g} s, but ring-down {outside[0] + 1} is at "
            f"{times_s[outside[0]]:.6g} s (device clock): a log of another run, or of another clock?"
        )
    return np.interp(times_s, times, values)


def load_table(
    source: MeasurementTable | Mapping[str, Any] | str | os.PathLike[str],
    drop_invalid: bool = False,
    **bag_options: Any,
) -> MeasurementTable:
    """A :class:`MeasurementTable` from a CSV file, a rosbag2 bag directory (or .mcap file),
    or a mapping of column arrays."""
    if isinstance(source, MeasurementTable):
        return source
    if isinstance(source, Mapping):
        return MeasurementTable({k: np.asarray(v, float) for k, v in source.items()}, "columns")
    if is_bag(source):
        return from_bag(pathlib.Path(source), **bag_options)
    return read_csv(source, drop_invalid=drop_invalid)


def is_bag(source: str | os.PathLike[str]) -> bool:
    """A rosbag2 bag: a directory or an .mcap file."""
    path = pathlib.Path(source)
    return path.is_dir() or path.suffix == ".mcap"


# --- bags -----------------------------------------------------------------------------------
def _stamp_s(message: Any, timestamp_ns: int) -> float:
    seconds = stamps.seconds(message.header.stamp)
    return seconds if seconds > 0 else 1e-9 * timestamp_ns


def from_bag(
    path: str | os.PathLike[str],
    reference: Reference | None = None,
    magnet_position_m: Vector = (0.0, 0.0, 0.0),
    ringdown_topic: str = RINGDOWN_TOPIC,
    sweep_topic: str = SWEEP_TOPIC,
    theta_stop_rad: float = PAPER_PROBE.theta_stop_rad,
) -> MeasurementTable:
    """A table from the project's bags: ``mows_msgs/msg/RingdownFit`` messages on
    ``ringdown_topic`` (only STATUS_OK fits; the others are counted in ``notes``).

    ``reference`` gives the reference field at the probe:

    - ``None``: no reference columns;
    - a topic name (``"/reference/magnetic_field"``): ``sensor_msgs/msg/MagneticField``
      messages, the one nearest in time to each ring-down (header stamps, global frame);
    - a static source in any form :func:`mows.lab.data.reference.reference_source` takes (a field
      source, its mapping or YAML file at ``magnet_position_m``, or a scenario at its magnet
      position): the exact field and in-plane gradient there.

    Rows are numbered into sweeps by the ``SweepDecomposition`` stamps on ``sweep_topic`` when
    the bag has them (a sweep's stamp is that of its last ring-down; a sweep of several probes
    publishes one per probe, with one stamp). Each row's start swing is
    :func:`start_amplitudes_rad`, with the probe's ``theta_stop_rad`` where no fit gives the stop.
    Fits of several probes (``probe_id``, docs/multi_probe.md) give the column ``probe``
    (:mod:`mows.lab.data.probe_rows`), so that the lab keeps each probe's rows apart.
    """
    path = pathlib.Path(path)
    if not path.exists():
        raise TableError(f"no bag at {path}")
    topics = [ringdown_topic, sweep_topic] + (
        [reference] if isinstance(reference, str) and reference.startswith("/") else []
    )
    fits: list[tuple[float, Any]] = []  # (stamp, RingdownFit message)
    sweeps: list[float] = []
    fields: list[tuple[float, tuple[float, float, float]]] = []
    failed = 0
    for item in bags.read_bag(path, topics=topics):
        if item.topic == ringdown_topic:
            if getattr(item.message, "tuning", False):
                continue
            if item.message.status == FitStatus.OK:
                fits.append((_stamp_s(item.message, item.timestamp_ns), item.message))
            else:
                failed += 1
        elif item.topic == sweep_topic:
            sweeps.append(_stamp_s(item.message, item.timestamp_ns))
        else:
            vector = item.message.magnetic_field
            fields.append((_stamp_s(item.message, item.timestamp_ns), (vector.x, vector.y, vector.z)))
    if not fits:
        raise TableError(
            f"{path}: no successful RingdownFit messages on {ringdown_topic}"
            + (f" ({failed} failed fits)" if failed else "")
        )
    fits.sort(key=lambda item: item[0])
    times_s = np.array([stamp for stamp, _ in fits])
    columns = {
        "theta0_deg": np.degrees([m.theta0_rad for _, m in fits]),
        "f_hz": np.array([m.frequency_hz for _, m in fits]),
        "f_std_hz": np.array([m.frequency_std_hz for _, m in fits]),
        "t_s": times_s - times_s[0],
        "damping_per_s": np.array([m.damping_per_s for _, m in fits]),
        "duration_s": np.array([m.duration_s for _, m in fits]),
        "snr_db": np.array([m.snr_db for _, m in fits]),
    }
    notes = [f"skipped {failed} RingdownFit messages whose status is not OK"] if failed else []
    sweep_ids = np.searchsorted(np.unique(sweeps), times_s - 1e-9).astype(float) if sweeps else np.zeros(len(fits))
    if sweeps:
        columns["sweep"] = sweep_ids
    probe_ids = np.array([getattr(m, "probe_id", 0) for _, m in fits], float)
    if len(np.unique(probe_ids)) > 1:
        columns[PROBE] = probe_ids
    start, said = start_amplitudes_rad([m for _, m in fits], sweep_ids, theta_stop_rad, probe_ids)
    columns["amplitude_deg"] = np.degrees(start)
    notes += said
    columns.update(_reference_columns(reference, times_s, fields, magnet_position_m, path))
    return with_notes(columns, str(path), notes)


def start_amplitudes_rad(
    fits: Sequence[Any], sweep_ids: np.ndarray, stop_rad: float, probe_ids: np.ndarray
) -> tuple[np.ndarray, list[str]]:
    """Each ring-down's start swing from RingdownFit messages (or fits), and notes of what was
    assumed or left out: the stop less the row's own |rest offset| where its fit determined it
    (:meth:`mows.sweep.record.SweepRecord.fitted_start_amplitudes_rad`, the rule of
    :func:`mows.physics.ringdown_average.swing_from_stop_rad`). The stop is pooled per sweep by a
    median with outliers left out (every ring-down of a sweep starts from the same housing
    stop, and a single fit's θmax is rarely determined), else over all rows, else ``stop_rad``
    (the probe's, NaN for none). Each probe's stop (``probe_ids``: one per fit) is its own
    housing's, pooled over its rows only. NaN where nothing gives a stop, never a swing ≤ 0."""
    record = SweepRecord([SweepPoint.from_fit(fit, math.nan, math.nan) for fit in fits])
    probe_ids = np.asarray(probe_ids, float)
    start = np.empty(len(fits))
    notes: list[str] = []
    for probe in np.unique(probe_ids):
        mine = np.flatnonzero(probe_ids == probe)
        everywhere = SweepRecord([record.points[i] for i in mine]).stop_amplitude_rad(fallback_rad=stop_rad)
        for sweep in np.unique(sweep_ids[mine]):
            rows = mine[sweep_ids[mine] == sweep]
            start[rows], said = SweepRecord([record.points[i] for i in rows]).fitted_start_amplitudes_rad(everywhere)
            label = (f"probe {probe:g} " if len(np.unique(probe_ids)) > 1 else "") + (
                f"sweep {sweep:g}" if len(np.unique(sweep_ids)) > 1 else ""
            )
            notes += [f"{label.strip()}: {note}" for note in said] if label else said
    return start, notes


def _reference_columns(
    reference: Reference | None,
    times_s: np.ndarray,
    fields: Sequence[tuple[float, tuple[float, float, float]]],
    magnet_position_m: Vector,
    path: pathlib.Path,
) -> dict[str, np.ndarray]:
    if reference is None:
        return {}
    if isinstance(reference, str) and reference.startswith("/"):
        if not fields:
            raise TableError(f"{path}: no sensor_msgs/msg/MagneticField messages on {reference}")
        times = np.array([t for t, _ in fields])
        values = np.array([v for _, v in fields])
        nearest = np.abs(times_s[:, None] - times[None, :]).argmin(axis=1)
        return dict(zip(FIELD, values[nearest].T))
    return reference_columns(reference, len(times_s), magnet_position_m)


def from_sweep(
    record: SweepRecord, reference: Reference, probe: Probe, decomposition: Decomposition | None = None
) -> MeasurementTable:
    """The table of one rotation sweep (:class:`mows.sweep.record.SweepRecord`) in a static
    ``reference`` (anything :func:`mows.lab.data.reference.reference_source` takes). With a first-principles
    ``decomposition`` of the sweep, each ring-down's start swing is stop − |θs| at its field
    (:meth:`~mows.sweep.record.SweepRecord.start_amplitudes_rad`); else each fit's own
    (:meth:`~mows.sweep.record.SweepRecord.fitted_start_amplitudes_rad`, the probe's stop where
    no fit gives it)."""
    starts = (
        record.start_amplitudes_rad(decomposition, probe)
        if decomposition is not None and decomposition.ok and decomposition.model == "first_principles"
        else record.fitted_start_amplitudes_rad(probe.theta_stop_rad)[0]
    )
    columns = record.table_columns(starts)
    columns.update(reference_columns(reference, len(record.points)))
    return MeasurementTable(columns, "sweep")


@dataclasses.dataclass(frozen=True)
class SweepReadings:
    """One probe's rotation sweep read from the f00 its ring-downs carry: by the first-principles
    model and by the published one (Eqs. 11, 12), and the lab's table of it."""

    f00_hz: float
    first_principles: Decomposition
    published: Decomposition
    table: MeasurementTable


def read_sweep(record: SweepRecord, reference: Reference, probe: Probe) -> SweepReadings:
    """``record`` (its successful ring-downs) decomposed both ways from the estimator's f00 of its
    ring-downs (:func:`mows.sweep.probes.f00_of`), and its table in the static ``reference``
    (:func:`from_sweep`, the start swings at the first-principles field)."""
    f00_hz = f00_of(record)
    first_principles = record.decompose(probe, f00_hz)
    published = record.decompose(probe, f00_hz, model="published")
    return SweepReadings(f00_hz, first_principles, published, from_sweep(record, reference, probe, first_principles))
