"""A rotation sweep of several probes at once: each ring-down window gives one fit per probe
(its ``probe_id``), each probe's fits make its own sweep record, and each record is decomposed
with its neighbours' fields in the model.

Each probe's record becomes a :class:`RecordSweep` and the probes are decomposed together by
:func:`mows.sweep.multiprobe.decompose_probes`: alone first
(:meth:`mows.sweep.record.SweepRecord.decompose`, the 3θ0 curvature fitted when the record has
the orientations it needs), then with the other probes' static dipole fields, gradients and
Hessians at its magnet as known terms of the first-principles model, their rest angles iterated
to the coupled fixed point from the others' estimates. What it reports is then each probe's
*external* field and gradient.

The probes sit at their ``position_m`` in the stage's rotation-plane frame, in parallel planes
(the decomposition is in-plane). Each ring-down's θ0 is the probe's own, as its fit says (the
stage's angle plus the probe's home orientation). Where probe k rang, a neighbour's moment is
turned to that neighbour's θ0 at the same step of the sweep (the same turn of the stage, whichever
group it was excited in), from its own fits of that step (:func:`orientations_rad`); at a step
where the neighbour has no successful fit, to the stage's angle there plus the neighbour's home
orientation, the mean of its fits' θ0 less the stage's angle over the steps where it has them.
The published model has no neighbour terms, a probe without a decomposition leaves its
neighbours' fields unknown, and magnets listed closer than :data:`MIN_APART_M` are no point
dipoles to each other: the probes are then decomposed alone, each report saying so.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Mapping, Sequence

import numpy as np

from mows.estimate.probe_set import ProbeEntry
from mows.physics.coupling import PlacedProbe
from mows.physics.pose import Pose
from mows.sweep.decompose import Decomposition, DecompositionStatus, NeighbourFields, orientations_problem
from mows.sweep.multiprobe import DEFAULT_PASSES, uncoupled
from mows.sweep.multiprobe import decompose_probes as decompose_together
from mows.sweep.record import SweepRecord

# Closer magnets are no point dipoles to each other: each swings on a lever of ~2 mm and is
# ~2 mm across, and a neighbour's field there varies over both.
MIN_APART_M = 0.01


@dataclasses.dataclass(frozen=True)
class ProbeDecomposition:
    """One probe's decomposed sweep: its id, decomposition, ring-downs and the f00 used."""

    probe_id: int
    decomposition: Decomposition
    record: SweepRecord
    f00_hz: float


@dataclasses.dataclass(frozen=True)
class ProbeDecompositions:
    """Every listed probe's decomposition, in id order."""

    probes: tuple[ProbeDecomposition, ...]

    @property
    def ok(self) -> bool:
        return all(p.decomposition.ok for p in self.probes)

    @property
    def message(self) -> str:
        """Why probes were not decomposed ('' when all were)."""
        return "; ".join(
            f"probe {p.probe_id}: {p.decomposition.message}" for p in self.probes if not p.decomposition.ok
        )

    def report(self) -> str:
        return "; ".join(f"probe {p.probe_id}: {_report(p.decomposition)}" for p in self.probes)


def f00_of(record: SweepRecord) -> float:
    """The estimator's f00 of a record's probe, as each OK ring-down carries it (frequency − shift)."""
    return float(np.mean([p.frequency_hz - p.shift_hz for p in record.points]))


@dataclasses.dataclass(frozen=True)
class RecordSweep:
    """One probe's record as its share of the sweep (:class:`mows.sweep.multiprobe.SweepOfProbe`):
    ``steps`` are the sweep's steps its points were taken at (in the record's order)."""

    entry: ProbeEntry
    record: SweepRecord
    steps: np.ndarray
    model: str
    f00_free: bool

    @property
    def placed(self) -> PlacedProbe:
        return PlacedProbe(self.entry.probe, Pose(magnet_position_m=self.entry.position_m))

    @property
    def theta0_rad(self) -> np.ndarray:
        return np.array([p.theta0_rad for p in self.record.points], float)

    def decompose(self, neighbours: NeighbourFields | None) -> Decomposition:
        """Its record decomposed, with the ``neighbours``' fields at its ring-downs when given."""
        record = self.record
        if not record.points:
            why = f"no successful ring-down of probe {self.entry.probe_id} ({record.failed} failed)"
            return Decomposition(self.model, DecompositionStatus.NO_DECOMPOSITION, why, f00_free=self.f00_free)
        curvature = self.model == "first_principles" and not orientations_problem(
            self.theta0_rad, self.f00_free, curvature=True
        )
        return record.decompose(
            self.entry.probe,
            f00_of(record),
            self.model,
            self.f00_free,
            neighbours,
            curvature=curvature,
            measured_swings=True,
        )


def decompose_probes(
    probes: tuple[ProbeEntry, ...],
    records: Mapping[int, SweepRecord],
    model: str,
    f00_free: bool,
    coupling: bool = True,
    passes: int = DEFAULT_PASSES,
    steps: Mapping[int, Sequence[int]] | None = None,
    stage_rad: Sequence[float] | None = None,
) -> ProbeDecompositions:
    """Every probe's sweep decomposed, with the coupling in the model unless ``coupling`` is
    False or it cannot be (module docstring). ``steps``: by probe id, the step of each point of
    its record; ``stage_rad``: the stage's angle at each step. Without them every record must
    hold one point per step, in order."""
    given = steps or {e.probe_id: range(len(records[e.probe_id].points)) for e in probes}
    sweeps = [RecordSweep(e, records[e.probe_id], np.asarray(given[e.probe_id], int), model, f00_free) for e in probes]
    crowded = crowding(probes)
    coupled = coupling and model == "first_principles" and not crowded
    orientations = None
    if coupled and len(probes) > 1 and steps is not None and stage_rad is not None:
        orientations = orientations_rad(sweeps, np.asarray(stage_rad, float))
    results = decompose_together(sweeps, coupled, passes, orientations)
    if coupling and not coupled and len(probes) > 1:
        results = [uncoupled(d, crowded) for d in results]
    return ProbeDecompositions(
        tuple(ProbeDecomposition(s.entry.probe_id, d, s.record, _f00_hz(s)) for s, d in zip(sweeps, results))
    )


def crowding(probes: Sequence[ProbeEntry]) -> str:
    """Why the probes cannot be point dipoles in each other's model, '' when they can: two
    magnets listed closer than :data:`MIN_APART_M` (e.g. a ``probes`` list without places)."""
    for a, b in itertools.combinations(probes, 2):
        apart_m = float(np.linalg.norm(np.subtract(a.position_m, b.position_m)))
        if apart_m < MIN_APART_M:
            return f"probes {a.probe_id} and {b.probe_id} are listed {apart_m * 1e3:.1f} mm apart (position_m)"
    return ""


def orientations_rad(sweeps: Sequence[RecordSweep], stage_rad: np.ndarray) -> np.ndarray:
    """(probes, steps): each probe's θ0 at each step of the sweep, from its own fits of that step;
    where it has none, the stage's angle there plus its home orientation (the circular mean of
    its fits' θ0 less the stage's angle at theirs). NaN for a probe with no fit at all (it has
    no decomposition, so the coupling is not put in the model)."""
    table = np.full((len(sweeps), len(stage_rad)), np.nan)
    for row, s in zip(table, sweeps):
        theta0 = s.theta0_rad
        if not theta0.size:
            continue
        home = float(np.angle(np.mean(np.exp(1j * (theta0 - stage_rad[s.steps])))))
        row[:] = stage_rad + home
        row[s.steps] = theta0
    return table


def _f00_hz(sweep: RecordSweep) -> float:
    return f00_of(sweep.record) if sweep.record.points else sweep.entry.f00_hz


def _report(d: Decomposition) -> str:
    """``d``'s report, with its notes when it succeeded."""
    return f"{d.report()} ({d.message})" if d.ok and d.message else d.report()
