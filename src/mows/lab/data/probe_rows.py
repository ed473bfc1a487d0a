"""A table's probes: each row's probe and its constants, and its neighbours' field at each row.

:class:`ProbeSet` is the one way the lab holds a table's probes: a table of one probe is a set
of one and takes the same path as several (:func:`probe_parts`).

A table may hold several probes that share a scene (docs/multi_probe.md). The column ``probe``
names each row's probe by an integer id; ``step`` numbers the steps of a sweep, so that rows
with equal ``sweep`` and ``step`` were measured together; ``magnet_x_m``, ``magnet_y_m`` and
``magnet_z_m`` give where the row's magnet sits undeflected (global frame, as
``--magnet-position`` does for one probe).

:func:`with_neighbour_field` gives every row its neighbours' field at its magnet: the exact
point-dipole field (Eq. S8 before its far-field reduction), with its in-plane gradient and
Hessian, of every other probe's magnet in the same sweep step. Each neighbour's moment points
along its row's orientation turned by its rest angle in that row's reference field, and its
magnet sits at the end of its lever turned likewise (:class:`mows.physics.pose.Pose`). The
``mutual_coupling`` effect adds these columns to the reference (:mod:`mows.lab.model.catalog`).
Because they are columns, each row's model stays a function of that row's own columns.

What the columns leave out: the neighbours' rest angles are taken in the reference field alone,
not in each other's fields, which changes the coupling by about m·B_neighbour/(kM·θ) ≈ 1e-4 at
centimetres (:mod:`mows.physics.coupling`). A ringing neighbour's field at its own frequency is
off this probe's resonance and is left out too (docs/multi_probe.md).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import NamedTuple

import numpy as np

from mows.estimate.probe_set import ProbeEntry
from mows.lab.data.table import MAGNET, NEIGHBOUR, PROBE, STEP, MeasurementTable, TableError, rows_text
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe
from mows.physics.sources import PointDipole


@dataclasses.dataclass(frozen=True)
class ProbeSet:
    """The probes of a table (``members``: one :class:`~mows.estimate.probe_set.ProbeEntry` per
    probe, in id order): how the lab holds a table's probes, for one probe as for several.

    ``column`` says whether the table's column ``probe`` names each row's probe. Without it,
    the set holds one probe (id 0), every row is its, and its f00 is the parameter ``f00_hz``;
    with it, probe i's f00 is ``probe_<i>.f00_hz``.

    The frequency model evaluates each probe's rows with that probe's own constants and fits one
    f00 per probe (:mod:`mows.lab.model.frequency_model`), and an effect sees each row's own
    probe. Where the diagnosis needs one probe's constants for the whole table (its explanatory
    texts, the physical range of an effect parameter all the probes share), it takes
    :attr:`first`'s.
    """

    members: tuple[ProbeEntry, ...]
    column: bool = True

    @classmethod
    def of(cls, probes: Mapping[int, Probe], column: bool = True) -> ProbeSet:
        """The set of ``probes`` ({id: constants}), named by the table's column ``probe`` unless
        ``column`` is False (then of one probe); ValueError when it is empty, or of several
        probes without the column."""
        ordered = tuple(ProbeEntry(i, probe, probe.f00_hz) for i, probe in sorted(probes.items()))
        if not ordered:
            raise ValueError("a probe set needs at least one probe")
        if not column and len(ordered) > 1:
            raise ValueError("a table that does not name its rows' probes holds one probe")
        return cls(ordered, column)

    @classmethod
    def one(cls, probe: Probe) -> ProbeSet:
        """The set of ``probe`` alone, the probe of every row of a table that does not name its
        rows' probes: how a probe file or a table's one probe enters the lab."""
        return cls.of({0: probe}, column=False)

    @classmethod
    def for_table(cls, table: MeasurementTable, default: Probe, named: Mapping[int, Probe]) -> ProbeSet:
        """The constants of every probe of ``table``: ``named`` by id, ``default`` for the others;
        TableError naming a probe that the table does not hold."""
        ids = np.unique(table.columns[PROBE]).astype(int).tolist() if table.has(PROBE) else []
        unknown = sorted(set(named) - set(ids))
        if unknown:
            raise TableError(
                f"probe file(s) given for probe {', '.join(map(str, unknown))}, which the table does not hold"
                + ("" if table.has(PROBE) else f" (it has no column '{PROBE}' saying which row is which probe)")
            )
        if not table.has(PROBE):
            return cls.one(default)
        return cls.of({i: named.get(i, default) for i in ids})

    @property
    def first(self) -> Probe:
        """The constants of the first probe (in id order): those the diagnosis takes for the
        whole table (class docstring)."""
        return self.members[0].probe

    @property
    def ids(self) -> tuple[int, ...]:
        return tuple(entry.probe_id for entry in self.members)

    @property
    def f00_names(self) -> list[str]:
        """Each probe's f00 parameter: ``probe_<id>.f00_hz``, or ``f00_hz`` for the probe of a
        table that does not name its rows' probes."""
        return [f"probe_{i}.f00_hz" for i in self.ids] if self.column else ["f00_hz"]

    def index(self, table: MeasurementTable) -> np.ndarray:
        """Each row's position in ``members`` (n,); TableError naming a probe without constants,
        or where the set is named by a column the table does not have."""
        if not self.column:
            return np.zeros(len(table), int)
        if not table.has(PROBE):
            raise TableError(
                f"constants of probes {', '.join(map(str, self.ids))} given, but the table has no column "
                f"'{PROBE}' saying which row is which probe"
            )
        ids = np.asarray(self.ids)
        found = np.searchsorted(ids, table.columns[PROBE].astype(int))
        known = (found < len(ids)) & (ids[np.minimum(found, len(ids) - 1)] == table.columns[PROBE])
        if not known.all():
            rows = np.flatnonzero(~known)
            raise TableError(
                f"probe {int(table.columns[PROBE][rows[0]])} in {rows_text(rows)} has no constants "
                f"(give --probe ID=FILE; known: {', '.join(map(str, self.ids))})"
            )
        return found


class ProbePart(NamedTuple):
    """The rows of one probe of a table: their indices, those rows as a table (the table itself
    when they are all its rows: the model's caches are kept per table), and the probe."""

    rows: np.ndarray
    table: MeasurementTable
    entry: ProbeEntry


def probe_parts(table: MeasurementTable, probes: ProbeSet) -> list[ProbePart]:
    """The part of ``table`` of each probe of ``probes`` that it holds, in id order."""
    index = probes.index(table)
    found = [np.flatnonzero(index == k) for k in range(len(probes.members))]
    return [
        ProbePart(rows, table if len(rows) == len(table) else table.subset(rows), entry)
        for rows, entry in zip(found, probes.members)
        if rows.size
    ]


def with_probes(table: MeasurementTable, probes: ProbeSet) -> tuple[MeasurementTable, ProbeSet]:
    """(table, probes) ready for the lab: the table's :class:`ProbeSet` (the probe of a set of one
    that names no id lent to every id of a table that names its rows' probes) and, for a table
    with a ``probe`` column, the neighbours' field (:func:`with_neighbour_field`). TableError for a
    set named by ids given with a table that does not say which row is which probe."""
    if table.has(PROBE) and not probes.column:
        probes = ProbeSet.for_table(table, probes.first, {})
    probes.index(table)
    return with_neighbour_field(table, probes), probes


def with_neighbour_field(table: MeasurementTable, probes: ProbeSet) -> MeasurementTable:
    """``table`` with the NEIGHBOUR columns (module docstring) where it holds two or more
    probes and says where they are and which rows were measured together; otherwise ``table``.
    Rows whose step lacks a neighbour's row are left out with a note (that neighbour's
    orientation, and so its field, is unknown there); TableError where a probe has two rows in
    one step."""
    index = probes.index(table)
    if len(np.unique(index)) < 2 or not all(table.has(name) for name in (STEP, *MAGNET)):
        return table
    _, step = np.unique(np.stack([table.sweep_ids, table.columns[STEP]], -1), axis=0, return_inverse=True)
    step = step.ravel()
    slot = np.full((step.max() + 1, len(probes.members)), -1)
    count = np.zeros_like(slot)
    np.add.at(count, (step, index), 1)
    repeated = np.flatnonzero(count[step, index] > 1)
    if repeated.size:
        raise TableError(
            f"probe {int(table.columns[PROBE][repeated[0]])} has more than one row in one sweep step: "
            f"{rows_text(repeated)} (columns sweep, step)"
        )
    slot[step, index] = np.arange(len(table))
    present = np.unique(index)
    lacking = np.flatnonzero(np.any(slot[step][:, present] < 0, axis=1))
    if lacking.size:
        kept = table.subset(np.setdiff1d(np.arange(len(table)), lacking))
        note = (
            f"left out {rows_text(lacking)}: a neighbour has no row in their sweep step, so its "
            "orientation there, and its field, are unknown"
        )
        table = dataclasses.replace(kept, notes=kept.notes + (note,))
        return with_neighbour_field(table, probes) if len(np.unique(probes.index(table))) > 1 else table
    return table.with_columns(**_neighbour_columns(table, probes, slot[step]))


def _neighbour_columns(table: MeasurementTable, probes: ProbeSet, partner: np.ndarray) -> dict[str, np.ndarray]:
    """The NEIGHBOUR columns; ``partner[r, k]`` is the row of member k in row r's step."""
    moments, positions = _magnets_at_rest(table, probes)
    points = np.stack([table.columns[name] for name in MAGNET], -1)
    n = len(table)
    field, gradient, hessian = np.zeros((n, 3)), np.zeros((n, 3, 3)), np.zeros((n, 3, 3, 3))
    for row in range(n):
        for source in partner[row]:
            if source != row:
                dipole = PointDipole(moments[source], positions[source])
                field[row] += dipole.field_t(points[row])
                gradient[row] += dipole.gradient_t_per_m(points[row])
                hessian[row] += dipole.hessian_t_per_m2(points[row])
    values = [field[:, 0], field[:, 1], field[:, 2], gradient[:, 0, 0], gradient[:, 0, 1], gradient[:, 1, 1]]
    values += [hessian[:, 0, 0, 0], hessian[:, 0, 0, 1], hessian[:, 0, 1, 1], hessian[:, 1, 1, 1]]
    return dict(zip(NEIGHBOUR, values))


def _magnets_at_rest(table: MeasurementTable, probes: ProbeSet) -> tuple[np.ndarray, np.ndarray]:
    """Each row's magnet as a neighbour sees it: moment (n, 3), A·m², and position (n, 3), m,
    at the rest angle in the row's reference field and gradient (module docstring)."""
    axes = table.probe_axes()
    field = table.probe_field_t
    gradient = np.einsum("nai,nij,nbj->nab", axes, table.gradient_t_per_m, axes)
    moments, positions = np.zeros((len(table), 3)), np.zeros((len(table), 3))
    index = probes.index(table)
    for k, entry in enumerate(probes.members):
        rows, probe = np.flatnonzero(index == k), entry.probe
        rest = ArcPotential.from_local_field(probe, field[rows], gradient[rows]).rest_angle_rad()
        for row, angle in zip(rows, rest):
            magnet = tuple(float(table.columns[name][row]) for name in MAGNET)
            pose = Pose(magnet_position_m=magnet, theta0_rad=float(table.theta0_rad[row]))
            moments[row] = probe.moment_am2 * pose.moment_direction_at(angle)
            positions[row] = pose.magnet_position_at(angle, probe.lever_m)
    return moments, positions
