"""A rotation sweep of several probes at once: each ring-down window gives one fit per probe
(its ``probe_id``), each probe's fits make its own sweep record, and each record is decomposed.

:func:`decompose_probe` is the seam where one probe's sweep becomes its field and gradient.
Today it is the single-probe decomposition of that probe's ring-downs
(:meth:`mows.sweep.record.SweepRecord.decompose`), which leaves the neighbours' static dipole
fields (:mod:`mows.physics.coupling`) in the field it reports. The decomposition with the
coupling in its model replaces it there; it is given every probe's record for that reason.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

import numpy as np

from mows.estimate.probe_set import ProbeEntry
from mows.sweep.decompose import Decomposition, DecompositionStatus
from mows.sweep.record import SweepRecord


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
        return "; ".join(f"probe {p.probe_id}: {p.decomposition.report()}" for p in self.probes)


def f00_of(record: SweepRecord) -> float:
    """The estimator's f00 of a record's probe, as each OK ring-down carries it (frequency − shift)."""
    return float(np.mean([p.frequency_hz - p.shift_hz for p in record.points]))


def decompose_probe(
    entry: ProbeEntry, records: Mapping[int, SweepRecord], model: str, f00_free: bool
) -> ProbeDecomposition:
    """Probe ``entry``'s sweep decomposed (module docstring: the single-probe decomposition of
    its own record; ``records`` holds every probe's, for the coupled one)."""
    record = records[entry.probe_id]
    if not record.points:
        why = f"no successful ring-down of probe {entry.probe_id} ({record.failed} failed)"
        failed = Decomposition(model, DecompositionStatus.NO_DECOMPOSITION, why, f00_free=f00_free)
        return ProbeDecomposition(entry.probe_id, failed, record, entry.f00_hz)
    f00_hz = f00_of(record)
    decomposition = record.decompose(entry.probe, f00_hz, model=model, f00_free=f00_free)
    return ProbeDecomposition(entry.probe_id, decomposition, record, f00_hz)


def decompose_probes(
    probes: tuple[ProbeEntry, ...], records: Mapping[int, SweepRecord], model: str, f00_free: bool
) -> ProbeDecompositions:
    """Every probe's sweep decomposed (:func:`decompose_probe`)."""
    return ProbeDecompositions(tuple(decompose_probe(entry, records, model, f00_free) for entry in probes))
