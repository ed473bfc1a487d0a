"""The measurement table: one row per ring-down result, its columns and their validation.

Readers (CSV, bags, sweeps) are in :mod:`mows.lab.data.readers`, over :mod:`mows.lab.data.intake`;
reference fields of static sources in :mod:`mows.lab.data.reference`.

Frame (the lab's contract with the user): the rotation plane is the global x–y plane, θ0 is
counted from +x towards +y, z completes a right-handed frame. The probe frame of a row is
x' = (cos θ0, sin θ0, 0), y' = (−sin θ0, cos θ0, 0), z' = z (docs/architecture.md).

Columns (CSV header names, SI units but for the ``*_deg`` columns):

=====================================  =========  ===================================================
``theta0_deg``, ``f_hz``, ``f_std_hz``  required   orientation, ring-down frequency and its std. uncertainty
``t_s``, ``sweep``                      optional   time; sweep number (CV holds out whole sweeps)
``ref_bx_t``, ``ref_by_t``, ``ref_bz_t``  optional   reference field at the probe, global frame
``ref_gxx_t_per_m``, ``ref_gxy_t_per_m``,  optional   in-plane reference gradient G_ij = ∂B_i/∂x_j
``ref_gyy_t_per_m``
``coil_current_a``, ``amplitude_deg``,  optional   covariates used by effects (``amplitude_deg`` is the
``temperature_k``, ``damping_per_s``,              swing at the first fitted sample about the rest
``duration_s``                                     angle, docs/model_lab.md; the last two as in
                                                   ``RingdownFit``)
``mows_table_format``                   optional   the marker of a table the project's own tools wrote
``probe``, ``step``, ``magnet_x_m``,     optional   a table of several probes: each row's probe id, its
``magnet_y_m``, ``magnet_z_m``                     sweep step and its magnet's position
                                                   (:mod:`mows.lab.data.probe_rows`)
any other numeric column                optional   kept as a covariate for the diagnostics
=====================================  =========  ===================================================

The rows a table refuses are those no bench produces (:func:`broken_rules`); a reader's columns
are made a table, with notes of what was assumed, by :mod:`mows.lab.data.intake`, which mends
rather than refuses the project's own tables (those with ``mows_table_format``).

The unmeasured gradient components are completed by Maxwell's equations for a field that is
static and source-free at the probe: Gxz = Gyz = 0 (unknown, taken as zero: they do not act
on a lever that swings in the plane) and Gzz = −(Gxx + Gyy) (∇·B = 0).
"""

from __future__ import annotations

import csv
import dataclasses
import os
from collections.abc import Iterable, Iterator, Mapping

import numpy as np

from mows.physics.pose import probe_axes
from mows.physics.ranges import RANGES

REQUIRED = ("theta0_deg", "f_hz", "f_std_hz")
FIELD = ("ref_bx_t", "ref_by_t", "ref_bz_t")
GRADIENT = ("ref_gxx_t_per_m", "ref_gxy_t_per_m", "ref_gyy_t_per_m")
# The curvature of a reference given as a field source (mows.lab.data.reference.with_reference):
# the in-plane Hessian at the probe, and how far it changes over the probe's placement.
CURVATURE = ("ref_hxxx_t_per_m2", "ref_hxxy_t_per_m2", "ref_hxyy_t_per_m2", "ref_hyyy_t_per_m2")
CURVATURE_SPREAD = "ref_h_spread_t_per_m2"
# Columns of a table of several probes (mows.lab.data.probe_rows).
PROBE = "probe"
STEP = "step"
KNOWN = (
    REQUIRED
    + ("t_s", "sweep", PROBE, STEP)
    + FIELD
    + GRADIENT
    + CURVATURE
    + (CURVATURE_SPREAD,)
    + ("coil_current_a", "amplitude_deg", "temperature_k", "damping_per_s", "duration_s")
)
MAGNET = ("magnet_x_m", "magnet_y_m", "magnet_z_m")
NEIGHBOUR_FIELD = ("neighbour_bx_t", "neighbour_by_t", "neighbour_bz_t")
NEIGHBOUR_GRADIENT = ("neighbour_gxx_t_per_m", "neighbour_gxy_t_per_m", "neighbour_gyy_t_per_m")
NEIGHBOUR_HESSIAN = (
    "neighbour_hxxx_t_per_m2",
    "neighbour_hxxy_t_per_m2",
    "neighbour_hxyy_t_per_m2",
    "neighbour_hyyy_t_per_m2",
)
NEIGHBOUR = NEIGHBOUR_FIELD + NEIGHBOUR_GRADIENT + NEIGHBOUR_HESSIAN
LABELS = ("sweep", PROBE, STEP)  # integer labels of rows, not quantities

MIN_SWEEPS = 10  # a subsample keeps at least this many sweeps (or all): folds for the cross-validation
POSITIVE = ("f_hz", "f_std_hz", "amplitude_deg", "duration_s", "temperature_k")
#: f_std_hz above f_hz/MAX_RELATIVE_STD is no measurement: a ring-down of a second pins f to a
#: fraction of a hertz (its Fourier width), and the lab's effects are millihertz.
MAX_RELATIVE_STD = 10.0
# A ring-down decays (δ ≥ 0) and its fit starts at or after the switch-off.
NON_NEGATIVE = ("damping_per_s", "start_offset_s")
# Columns of a quantity with a physical range (mows.physics.ranges), and the quantity.
RANGED_COLUMNS = {"temperature_k": "temperature_k", "coil_current_a": "coil_current_a", "duration_s": "duration_s"}
WRITER_COLUMN = "mows_table_format"  # the marker of the project's own tables (module docstring)
DERIVED = ("b_abs_t", "b_along_t", "b_perp_t", "b_normal_t", "g_t_per_m", "g_xy_t_per_m", "g_yy_t_per_m")
COVARIATE_DERIVED = ("b_abs_t", "b_perp_t", "b_along_t", "g_t_per_m")  # what the diagnostics test
NOT_COVARIATES = {"theta0_deg", "f_hz", "f_std_hz", "sweep", "ref_bx_t", "ref_by_t", WRITER_COLUMN, PROBE, STEP}
NOT_COVARIATES |= set(MAGNET + NEIGHBOUR)  # where a probe is and what its neighbours make: the model's inputs
NOT_COVARIATES |= {*CURVATURE, CURVATURE_SPREAD}  # what the reference's sources allow, not a quantity of the row


class TableError(ValueError):
    """A measurement table that cannot be used, with the column and rows at fault."""


class MissingColumnError(AttributeError, KeyError):
    """An effect or plugin asked for a column the table does not have."""

    def __init__(self, column: str) -> None:
        super().__init__(column)
        self.column = column

    def __str__(self) -> str:
        return f"the table has no column '{self.column}'"


def rows_text(rows: Iterable[int | np.integer]) -> str:
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
    notes: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        columns = {name: np.asarray(values, float) for name, values in self.columns.items()}
        object.__setattr__(self, "columns", columns)
        _validate(columns)

    @property
    def written_by_mows(self) -> bool:
        """True for a table the project's own tools wrote (module docstring)."""
        return self.has(WRITER_COLUMN)

    # --- plain columns --------------------------------------------------------------------
    def __getattr__(self, name: str) -> np.ndarray:
        columns = self.__dict__.get("columns", {})
        if name in columns:
            return columns[name]
        if name in DERIVED and "columns" in self.__dict__:
            derived = self.derived_columns()
            if name in derived:
                return derived[name]
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
    def amplitude_rad(self) -> np.ndarray | None:
        return np.radians(self.columns["amplitude_deg"]) if self.has("amplitude_deg") else None

    # --- reference field in the global frame ------------------------------------------------
    @property
    def field_t(self) -> np.ndarray:
        """Reference field (n, 3), global frame; zero where the table has none."""
        return np.stack([self.columns.get(name, np.zeros(len(self))) for name in FIELD], -1)

    @property
    def gradient_t_per_m(self) -> np.ndarray:
        """Reference gradient tensor (n, 3, 3), completed by Maxwell (module docstring)."""
        return in_plane_gradient(*(self.columns.get(name, np.zeros(len(self))) for name in GRADIENT))

    def probe_axes(self) -> np.ndarray:
        """Rows x', y', z' of each measurement as (n, 3, 3): ``axes @ v`` is v in the probe frame."""
        return probe_axes(self.theta0_rad)

    @property
    def probe_field_t(self) -> np.ndarray:
        """Reference field (n, 3) in the probe frame: Bx' along the axis, By' = B⊥ across it."""
        return np.einsum("nij,nj->ni", self.probe_axes(), self.field_t)

    # --- diagnostics --------------------------------------------------------------------------
    def derived_columns(self) -> dict[str, np.ndarray]:
        """The reference in the probe frame, by name (also attributes, ``rows.b_along_t``, for
        plugins): |B| ``b_abs_t``, Bx' ``b_along_t``, By' = B⊥ ``b_perp_t``, Bz ``b_normal_t``;
        G = Gx'x' ``g_t_per_m``, Gx'y' ``g_xy_t_per_m``, Gy'y' ``g_yy_t_per_m``. Only those of
        the reference the table has."""
        found: dict[str, np.ndarray] = {}
        if any(self.has(name) for name in FIELD):
            field = self.probe_field_t
            found.update(b_abs_t=np.linalg.norm(self.field_t, axis=-1), b_perp_t=field[:, 1], b_along_t=field[:, 0])
            found["b_normal_t"] = field[:, 2]
        if any(self.has(name) for name in GRADIENT):
            axes = self.probe_axes()
            gradient = np.einsum("nai,nij,nbj->nab", axes, self.gradient_t_per_m, axes)
            found.update(g_t_per_m=gradient[:, 0, 0], g_xy_t_per_m=gradient[:, 0, 1], g_yy_t_per_m=gradient[:, 1, 1])
        return found

    def covariates(self) -> dict[str, np.ndarray]:
        """Every quantity a residual may follow, by name: the table's numeric columns (time,
        current, amplitude, temperature, reference z, extras) and the reference's |B|, B⊥ = By',
        Bx' and G = Gx'x'. Constant ones are left out (a constant is absorbed by f00)."""
        found = {
            name: values
            for name, values in self.columns.items()
            if name not in NOT_COVARIATES and np.isfinite(values).all()  # our amplitude_deg may hold NaN
        }
        derived = self.derived_columns()
        found.update({name: derived[name] for name in COVARIATE_DERIVED if name in derived})
        return {name: values for name, values in found.items() if np.ptp(values) > 0}

    # --- derived tables ---------------------------------------------------------------------
    def subset(self, rows: np.ndarray) -> MeasurementTable:
        """The table restricted to ``rows`` (a boolean mask or indices)."""
        return dataclasses.replace(self, columns={k: v[rows] for k, v in self.columns.items()})

    def subsample(self, rows: int, seed: int = 0) -> MeasurementTable:
        """At most ``rows`` rows, stratified (:func:`stratified_rows`), with a note that says so."""
        chosen = stratified_rows(self.sweep_ids, rows, seed)
        if len(chosen) == len(self):
            return self
        sweeps = len(np.unique(self.sweep_ids))
        kept = len(np.unique(self.sweep_ids[chosen]))
        whole = "whole sweeps" if kept < sweeps else "rows from every sweep"
        note = (
            f"the table has {len(self)} rows: analysed on a random subsample of {len(chosen)} ({whole}: "
            f"{kept} of its {sweeps} sweep{'s' if sweeps > 1 else ''}, spread evenly over the table, seed {seed}); "
            "a weak effect may be significant only with all rows (--all-rows, slower)"
        )
        subset = self.subset(chosen)
        return dataclasses.replace(subset, notes=subset.notes + (note,))

    def without_rows(self, reasons: Mapping[int, tuple[str, str]]) -> MeasurementTable:
        """The table without the rows ``reasons`` names ({row index: (why, detail)}), with a
        note per reason that lists its rows and their details."""
        by_reason: dict[str, list[tuple[int, str]]] = {}
        for row, (reason, detail) in reasons.items():
            by_reason.setdefault(reason, []).append((row, detail))
        notes = tuple(
            f"left out {rows_text([row for row, _ in rows])}: {reason}"
            + (f" ({', '.join(detail for _, detail in rows)})" if any(detail for _, detail in rows) else "")
            for reason, rows in by_reason.items()
        )
        keep = np.ones(len(self), bool)
        keep[list(reasons)] = False
        return dataclasses.replace(self.subset(keep), notes=self.notes + notes)

    def with_columns(self, **columns: np.ndarray) -> MeasurementTable:
        """A copy with columns replaced or added (arrays of length n)."""
        return dataclasses.replace(self, columns={**self.columns, **columns})

    def concatenate(self, other: MeasurementTable) -> MeasurementTable:
        """Rows of both tables; they must have the same columns."""
        if set(self.columns) != set(other.columns):
            raise TableError(f"cannot join tables with columns {sorted(self.columns)} and {sorted(other.columns)}")
        return dataclasses.replace(
            self, columns={k: np.concatenate([v, other.columns[k]]) for k, v in self.columns.items()}
        )

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        names = list(self.columns)
        with open(path, "w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(names)
            for row in zip(*(self.columns[name] for name in names)):
                writer.writerow([repr(float(v)) for v in row])


def in_plane_gradient(gxx: np.ndarray, gxy: np.ndarray, gyy: np.ndarray) -> np.ndarray:
    """The gradient tensors (n, 3, 3) of in-plane components (n,), completed by Maxwell (module docstring)."""
    g = np.zeros((len(gxx), 3, 3))
    g[:, 0, 0], g[:, 0, 1], g[:, 1, 0], g[:, 1, 1] = gxx, gxy, gxy, gyy
    g[:, 2, 2] = -(gxx + gyy)
    return g


def _validate(columns: dict[str, np.ndarray]) -> None:
    missing = [name for name in REQUIRED if name not in columns]
    if missing:
        raise TableError(
            f"missing required column{'s' if len(missing) > 1 else ''} {', '.join(missing)} "
            f"(required: {', '.join(REQUIRED)})"
        )
    lengths = {name: len(values) for name, values in columns.items()}
    if len(set(lengths.values())) > 1:
        raise TableError(f"columns have different lengths: {lengths}")
    if lengths["f_hz"] == 0:
        raise TableError("the table has no rows")
    own = WRITER_COLUMN in columns  # our own start swings may be NaN (mows.lab.data.intake)
    for name, rule, rows in broken_rules(columns):
        if own and name == "amplitude_deg" and not np.any(columns[name][rows] <= 0):
            continue
        raise TableError(f"column '{name}' {rule} in {rows_text(rows)}")
    for group in (FIELD[:2], GRADIENT):
        given = [name for name in group if name in columns]
        if given and len(given) != len(group):
            raise TableError(
                f"column{'s' if len(given) > 1 else ''} {', '.join(given)} given without "
                f"{', '.join(sorted(set(group) - set(given)))}: give all of {', '.join(group)}"
            )
    for name in LABELS:
        if name in columns and np.any(columns[name] != np.round(columns[name])):
            raise TableError(
                f"column '{name}' must hold integers: not so in "
                f"{rows_text(np.flatnonzero(columns[name] != np.round(columns[name])))}"
            )


def rows_outside(values: np.ndarray, interval: tuple[float, float]) -> np.ndarray:
    """The rows whose |value| lies outside ``interval`` (low, high)."""
    low, high = interval
    return np.flatnonzero((np.abs(values) < low) | (np.abs(values) > high))


def broken_rules(columns: Mapping[str, np.ndarray]) -> Iterator[tuple[str, str, np.ndarray]]:
    """(column, rule, rows) for the values no column may hold: NaN or ±inf anywhere, values
    ≤ 0 in the columns that are positive by nature and < 0 in those that are not negative."""
    for name, values in columns.items():
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            yield name, "has NaN or infinite values", bad
    for name in POSITIVE:
        if name in columns:
            bad = np.flatnonzero(columns[name] <= 0)
            if bad.size:
                yield name, "must be > 0: not so", bad
    for name in NON_NEGATIVE:
        if name in columns:
            bad = np.flatnonzero(columns[name] < 0)
            if bad.size:
                yield name, "must be ≥ 0: not so", bad
    if "f_hz" in columns and "f_std_hz" in columns:
        bad = np.flatnonzero(columns["f_std_hz"] * MAX_RELATIVE_STD > columns["f_hz"])
        if bad.size:
            rule = f"must be below 1/{MAX_RELATIVE_STD:g} of f_hz (no ring-down measures f that poorly; another unit?)"
            yield "f_std_hz", f"{rule}: not so", bad
        floor = RANGES["f_rel_std"].possible[0]
        measured = columns["f_hz"] <= RANGES["frequency_hz"].possible[1]  # beyond: said of f_hz, as kHz
        bad = np.flatnonzero(measured & (columns["f_std_hz"] < floor * columns["f_hz"]))
        if bad.size:
            rule = f"must be at least {floor:g} of f_hz (no clock, no ring-down measures f better)"
            yield "f_std_hz", f"{rule}: not so", bad
    for name, quantity in RANGED_COLUMNS.items():
        if name in columns:
            bounds = RANGES[quantity]
            bad = rows_outside(columns[name], bounds.possible)
            if bad.size:
                yield (
                    name,
                    f"must lie within {bounds.text(bounds.possible)} as on any bench ({bounds.hint}): not so",
                    bad,
                )
    if PROBE in columns:
        bad = np.flatnonzero(columns[PROBE] < 0)
        if bad.size:
            yield PROBE, "is a probe id, 0 or more: not so", bad


#: Fewer rows than this test no model: the base model's parameters take them all, or nearly.
MIN_ROWS = 3


def check_design(table: MeasurementTable) -> None:
    """ValueError for a table that cannot test a model, with what to measure instead: too few
    rows, rows that are copies of one measurement, every row at one orientation in one field."""
    n = len(table)
    if n < MIN_ROWS:
        raise TableError(
            f"{table.source}: {n} row{'s leave' if n != 1 else ' leaves'} no degrees of freedom to test any model: "
            f"measure at least {MIN_ROWS} orientations"
        )
    c = table.columns
    fields = [c[name] for name in FIELD + GRADIENT if name in c]
    design = np.column_stack([c["theta0_deg"] % 360.0, *fields])
    if len(np.unique(np.column_stack([design, c["f_hz"], c["f_std_hz"]]), axis=0)) == 1:
        raise TableError(
            f"{table.source}: all {n} rows are one measurement (θ0, f_hz and f_std_hz alike to every digit): "
            "copies, not measurements; give each ring-down's own result"
        )
    if len(np.unique(design, axis=0)) == 1:
        raise TableError(
            f"{table.source}: every row is at θ0 = {c['theta0_deg'][0] % 360.0:g}° in one field: nothing varies "
            "that a model could be tested on; measure at several orientations (a sweep) or in several fields"
        )


def stratified_rows(sweep_ids: np.ndarray, rows: int, seed: int = 0) -> np.ndarray:
    """Indices (ascending) of at most ``rows`` rows that stand for the whole table.

    Whole sweeps first, so that each keeps its orientations and the cross-validation
    its whole-sweep folds: the sweeps, in order of first appearance, are cut into as many
    strata of consecutive sweeps as there is room for average sweeps (at least MIN_SWEEPS), and
    one sweep is drawn from each (the drift over the table is sampled end to end). When that
    leaves more than ``rows`` rows (long sweeps), each kept sweep gives rows in proportion to
    its length, drawn evenly along it: one at random from each run of consecutive rows.
    """
    rng = np.random.default_rng(seed)
    if len(sweep_ids) <= rows:
        return np.arange(len(sweep_ids))
    unique, first, inverse, counts = np.unique(sweep_ids, return_index=True, return_inverse=True, return_counts=True)
    order = np.argsort(first)  # sweeps in table order
    strata = min(len(unique), max(MIN_SWEEPS, round(rows / counts.mean())))
    bounds = np.linspace(0, len(unique), strata + 1).astype(int)
    picked = order[[rng.integers(low, high) for low, high in zip(bounds[:-1], bounds[1:])]]
    members = _members(inverse, picked)
    sizes = np.array([len(m) for m in members])
    if sizes.sum() <= rows:
        return np.sort(np.concatenate(members))
    share = rows * sizes / sizes.sum()
    quotas = np.floor(share).astype(int)
    quotas[np.argsort(quotas - share)[: rows - quotas.sum()]] += 1  # largest remainders: ``rows`` in all
    return np.sort(np.concatenate([_evenly(m, quota, rng) for m, quota in zip(members, quotas)]))


def _members(inverse: np.ndarray, picked: np.ndarray) -> list[np.ndarray]:
    """Rows of each sweep in ``picked`` (by its index into the unique sweeps), in one pass."""
    rows = np.flatnonzero(np.isin(inverse, picked))
    by_sweep = np.argsort(inverse[rows], kind="stable")
    rows = rows[by_sweep]
    starts = np.searchsorted(inverse[rows], np.sort(picked))
    return np.split(rows, starts[1:])


def _evenly(rows: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` of ``rows``: one drawn at random from each of ``count`` runs of consecutive rows."""
    bounds = np.linspace(0, len(rows), count + 1).astype(int)
    return rows[bounds[:-1] + (rng.random(count) * (bounds[1:] - bounds[:-1])).astype(int)]
