"""A rotation sweep of several probes at once: each ring-down window gives one fit per probe
(its ``probe_id``), each probe's fits make its own sweep record, and each record is decomposed
with its neighbours' fields in the model.

Each probe is first decomposed alone (:meth:`mows.sweep.record.SweepRecord.decompose`). With the
first-principles model, every probe is then decomposed again with the other probes' static
dipole fields, gradients and Hessians at its magnet as known terms of the model, their rest
angles iterated to the coupled fixed point at each of its orientations from the others'
estimates (:func:`mows.sweep.multiprobe.neighbour_fields`). What it reports is then each
probe's *external* field and gradient. The probes sit at their ``position_m`` in the stage's
rotation-plane frame and are all turned to the θ0 the driver announces, so a neighbour's
orientation at a ring-down is that ring-down's θ0; the planes are parallel (the decomposition
is in-plane). The published model has no neighbour terms, and a probe without a
decomposition leaves its neighbours' fields unknown: the probes are then decomposed alone,
each report saying so.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from mows.estimate.probe_set import ProbeEntry
from mows.physics.coupling import PlacedProbe
from mows.physics.pose import Pose
from mows.sweep.decompose import Decomposition, DecompositionStatus, NeighbourFields
from mows.sweep.multiprobe import DEFAULT_PASSES, ProbeSweep, neighbour_fields
from mows.sweep.record import SweepRecord

UNCOUPLED_NOTE = "decomposed without its neighbours' fields"


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


def decompose_probe(
    entry: ProbeEntry,
    records: Mapping[int, SweepRecord],
    model: str,
    f00_free: bool,
    neighbours: NeighbourFields | None = None,
) -> ProbeDecomposition:
    """Probe ``entry``'s sweep decomposed from its own record (``records`` holds every probe's),
    with the ``neighbours``' fields at each of its ring-downs when given."""
    record = records[entry.probe_id]
    if not record.points:
        why = f"no successful ring-down of probe {entry.probe_id} ({record.failed} failed)"
        failed = Decomposition(model, DecompositionStatus.NO_DECOMPOSITION, why, f00_free=f00_free)
        return ProbeDecomposition(entry.probe_id, failed, record, entry.f00_hz)
    f00_hz = f00_of(record)
    decomposition = record.decompose(entry.probe, f00_hz, model=model, f00_free=f00_free, neighbours=neighbours)
    return ProbeDecomposition(entry.probe_id, decomposition, record, f00_hz)


def decompose_probes(
    probes: tuple[ProbeEntry, ...],
    records: Mapping[int, SweepRecord],
    model: str,
    f00_free: bool,
    coupling: bool = True,
    passes: int = DEFAULT_PASSES,
) -> ProbeDecompositions:
    """Every probe's sweep decomposed, with the coupling in the model unless ``coupling`` is
    False or it cannot be (module docstring)."""
    results = [decompose_probe(entry, records, model, f00_free) for entry in probes]
    if not coupling or len(probes) < 2:
        return ProbeDecompositions(tuple(results))
    if model != "first_principles" or not all(r.decomposition.ok for r in results):
        return ProbeDecompositions(tuple(_uncoupled(r) for r in results))
    for _ in range(passes):
        parameters = [r.decomposition.parameters for r in results]
        coupled = [
            decompose_probe(entry, records, model, f00_free, _neighbours_of(k, probes, records, parameters))
            for k, entry in enumerate(probes)
        ]
        if not all(r.decomposition.ok for r in coupled):
            return ProbeDecompositions(tuple(_uncoupled(r) for r in results))
        results = coupled
    return ProbeDecompositions(tuple(results))


def _neighbours_of(
    index: int, probes: tuple[ProbeEntry, ...], records: Mapping[int, SweepRecord], parameters: list[np.ndarray]
) -> NeighbourFields:
    """The other probes' fields at probe ``index``'s magnet at each of its ring-downs, every probe
    turned to that ring-down's θ0 with its estimated external field and gradient."""
    theta0 = np.array([p.theta0_rad for p in records[probes[index].probe_id].points])
    zeros = np.zeros_like(theta0)
    sweeps = [
        ProbeSweep(PlacedProbe(e.probe, Pose(magnet_position_m=e.position_m)), e.f00_hz, theta0, zeros, zeros)
        for e in probes
    ]
    return neighbour_fields(sweeps, parameters)[index]


def _uncoupled(result: ProbeDecomposition) -> ProbeDecomposition:
    """``result`` with its report saying the neighbours' fields are left in its field."""
    d = result.decomposition
    if not d.ok:
        return result
    return dataclasses.replace(result, decomposition=dataclasses.replace(d, message=_joined(d.message, UNCOUPLED_NOTE)))


def _report(d: Decomposition) -> str:
    """``d``'s report, with its notes when it succeeded."""
    return f"{d.report()} ({d.message})" if d.ok and d.message else d.report()


def _joined(message: str, note: str) -> str:
    return f"{message}; {note}" if message else note
