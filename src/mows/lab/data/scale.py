"""A table's numbers held against its probes' scale, before any fit: ring-down frequencies near
each probe's f00, and a reference field a ring-down of the probe could be measured in (Eq. 6).

What is refused is what no bench produces: a column in the wrong unit (kHz; mT, gauss or µT
given as T), another probe's table, or several probes' rows in one table that does not say
which is which. Each refusal is a ValueError naming the column, the rows and the likely cause.
Physics is never refused: ring-downs that move with the reference by a factor that is no unit
(a weak field on a tilted plane, where gravity's torque nearly cancels the field's, gives 12.7)
are what the lab is for, and the table goes on with a note saying so.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from mows.estimate.probe_set import ProbeEntry
from mows.lab.data.probe_rows import ProbeSet, probe_parts
from mows.lab.data.table import FIELD, GRADIENT, PROBE, MeasurementTable, rows_text
from mows.physics.frequency import field_spring_nm_per_rad, gradient_spring_nm_per_rad
from mows.physics.probe import Probe

#: Ring-down frequencies this far (a factor) from the probe's f00 are no ring-downs of it: a
#: unit error (kHz) or another probe. The strongest fields of the paper move f by a factor ~2.
FREQUENCY_FACTOR = 10.0
#: The factors a reference in the wrong unit puts between the ring-downs' response and Eq. 6's:
#: mT, gauss or µT given as T (and the inverse), with the words for each.
UNIT_FACTORS = {1e3: "mT", 1e4: "gauss", 1e6: "µT"}
#: How near (a factor) a response must come to a unit factor to be called one: the physics the
#: model leaves out changes the response by less than this (gravity against a weak field: 12.7
#: lies a factor 79 from 10³).
UNIT_TOLERANCE = 2.0
#: A response this far (a factor) from Eq. 6's is said in a note: physics the model must find.
NOTE_FACTOR = 2.0
#: Rows of one configuration whose frequencies split by more than this share of f00 (a few
#: hundred times what a drift of one sweep moves them) are several probes': two probes of one
#: make differ by percents.
PROBE_GAP = 0.01


def table_probes(table: MeasurementTable, default: Probe, named: Mapping[int, Probe]) -> ProbeSet:
    """The probes of ``table`` (:meth:`ProbeSet.for_table`: ``named`` by id, ``default`` for the
    others); each probe's frequencies checked against its f00, and a table without the column
    ``probe`` that holds several probes' rows refused (:func:`check_one_probe`)."""
    if named and not table.has(PROBE):
        raise ValueError(
            f"--probe ID=FILE given for probe {', '.join(map(str, named))}, but the table has no "
            f"column '{PROBE}' saying which row is which probe"
        )
    probes = ProbeSet.for_table(table, default, named)
    for _, part, entry in probe_parts(table, probes):
        check_frequencies(part.columns["f_hz"], entry.probe, f"f_hz{_of_probe(probes, entry)}")
    if not probes.column:
        check_one_probe(table, default)
    return probes


def check_frequencies(f_hz: ArrayLike, probe: Probe, what: str = "f_hz") -> None:
    """ValueError when ring-down frequencies are not finite or their median lies more than
    FREQUENCY_FACTOR from the probe's f00 (in kHz, or of another probe)."""
    f_hz = np.asarray(f_hz, float)
    bad = np.flatnonzero(~np.isfinite(f_hz))
    if bad.size:
        raise ValueError(f"{what} = {f_hz[bad[0]]} (ring-down {bad[0] + 1}) is not a finite frequency")
    median = float(np.median(f_hz)) if f_hz.size else probe.f00_hz
    if not probe.f00_hz / FREQUENCY_FACTOR <= median <= probe.f00_hz * FREQUENCY_FACTOR:
        raise ValueError(
            f"{what}: the median ring-down frequency {median:.6g} Hz is far from the probe's "
            f"f00 = {probe.f00_hz:.4g} Hz (more than a factor {FREQUENCY_FACTOR:g}): a column in kHz, or another probe?"
        )


def check_one_probe(table: MeasurementTable, probe: Probe) -> None:
    """ValueError when rows measured in one configuration (one sweep, orientation and reference)
    ring at frequencies in separate groups more than PROBE_GAP·f00 apart, the same number of groups
    in most configurations: several probes' rows in a table without the column ``probe``."""
    names = ["theta0_deg", *(name for name in (*FIELD, *GRADIENT) if table.has(name))]
    keys = np.column_stack([table.sweep_ids, *(table.columns[name] for name in names)])
    _, cell = np.unique(keys, axis=0, return_inverse=True)
    groups = []
    for rows in (np.flatnonzero(cell.ravel() == c) for c in range(int(cell.max()) + 1)):
        if rows.size > 1:
            gaps = np.diff(np.sort(table.f_hz[rows]))
            groups.append(1 + int(np.sum(gaps > PROBE_GAP * probe.f00_hz)))
    if not groups:
        return
    count = int(np.median(groups))
    if count > 1:
        raise ValueError(
            f"{table.source}: rows measured in the same sweep, orientation and reference ring at {count} "
            f"frequencies more than {PROBE_GAP * probe.f00_hz:.3g} Hz apart ({len(groups)} configurations): "
            f"several probes in one table? Give the column '{PROBE}' saying which row is which probe "
            "(docs/multi_probe.md)"
        )


def check_reference(table: MeasurementTable, probes: ProbeSet, trust_scale: bool = False) -> MeasurementTable:
    """``table``, with a note where its ring-downs move with the reference otherwise than Eq. 6
    says; ValueError where a row's reference field or gradient is one no ring-down of ``probes``
    could be measured in: its spring alone, kB = m·|B| or kG = l·m·|G| (Eq. 6), would move f by more
    than FREQUENCY_FACTOR from f00 (k/kM > FREQUENCY_FACTOR²), where check_frequencies has
    found the measured ones (a column in mT or µT given as T, or another bench's reference), or
    where the ring-downs move a unit factor more or less than it says (:func:`reference_response`).
    ``trust_scale`` takes the reference as given in both cases."""
    probe = probes.first  # the scale of a unit: any probe's constants give it
    springs = {
        "field": (FIELD, probe.moment_am2, "T"),
        "gradient": (GRADIENT, probe.lever_m * probe.moment_am2, "T/m"),
    }
    for what, (names, per_unit, unit) in springs.items():
        given = [table.columns[name] for name in names if table.has(name)]
        if not given or trust_scale:
            continue
        size = np.max(np.abs(given), axis=0)
        bad = np.flatnonzero(per_unit * size / probe.spring_nm_per_rad > FREQUENCY_FACTOR**2 - 1.0)
        if bad.size:
            raise ValueError(
                f"{table.source}: the reference {what} {size[bad[0]]:.4g} {unit} ({rows_text(bad)}) would by "
                f"itself move the frequency more than a factor {FREQUENCY_FACTOR:g} from f00 (Eq. 6): "
                f"a column in m{unit} or µ{unit} given in {unit}? (--trust-reference takes it as given)"
            )
    notes: list[str] = []
    for _, part, entry in probe_parts(table, probes):
        whose = _of_probe(probes, entry)
        response = reference_response(part, entry.probe)
        if response is None:
            continue
        slope, spread_hz = response
        found = unit_factor(slope)
        said = (
            f"the ring-downs{whose} move {abs(slope):.3g} times as much as the reference field and gradient "
            f"say they must (Eq. 6, spread {spread_hz:.3g} Hz predicted)"
        )
        if found is not None and not trust_scale:
            factor, name = found
            raise ValueError(
                f"{table.source}: {said}: a factor 10^{round(math.log10(factor))} is a unit, the reference in "
                f"{name} given in T? (--trust-reference takes it as given)"
            )
        if not 1.0 / NOTE_FACTOR <= abs(slope) <= NOTE_FACTOR:
            notes.append(f"{said}: physics the model must find (gravity against a weak field, a moment off its file)")
    return dataclasses.replace(table, notes=table.notes + tuple(notes)) if notes else table


def _of_probe(probes: ProbeSet, entry: ProbeEntry) -> str:
    """ " of probe <id>" where the table names its rows' probes, for messages."""
    return f" of probe {entry.probe_id}" if probes.column else ""


def unit_factor(slope: float) -> tuple[float, str] | None:
    """(factor, unit) when ``slope`` (the ring-downs' response over Eq. 6's) lies within
    UNIT_TOLERANCE of 1/factor or factor for a factor of UNIT_FACTORS, else None."""
    size = abs(slope)
    for factor, name in UNIT_FACTORS.items():
        for near in (1.0 / factor, factor):
            if size > 0 and abs(math.log(size / near)) <= math.log(UNIT_TOLERANCE):
                return factor, name
    return None


#: A predicted spread of frequencies this many times the measurement's noise makes the
#: reference's scale measurable against the ring-downs.
SCALE_EVIDENCE_SIGMAS = 10.0


def reference_response(table: MeasurementTable, probe: Probe) -> tuple[float, float] | None:
    """(response, predicted spread in Hz): how much the ring-downs' spring moves per the spring
    Eq. 6 gives each row's reference (its field and gradient along the probe's axis), s = k/kM − 1.
    Eq. 6 is f² = f00²·(1 + s), linear in s, so the weighted line f² = a + b·s gives the response
    b/a with f00 free: 1 for a reference in tesla, exactly 10⁻³ for one in mT given as T, however
    strong. None where the reference's predicted spread, f00·std(s)/2, does not stand
    SCALE_EVIDENCE_SIGMAS above the noise (nothing to judge)."""
    derived = table.derived_columns()
    if "b_along_t" not in derived and "g_t_per_m" not in derived:
        return None
    spring = field_spring_nm_per_rad(probe.moment_am2, derived.get("b_along_t", 0.0)) + gradient_spring_nm_per_rad(
        probe.moment_am2, probe.lever_m, derived.get("g_t_per_m", 0.0)
    )
    predicted = spring / probe.spring_nm_per_rad * np.ones(table.n)
    spread_hz = 0.5 * probe.f00_hz * float(np.std(predicted))
    if table.n < 3 or spread_hz < SCALE_EVIDENCE_SIGMAS * float(np.median(table.f_std_hz)):
        return None
    slope, intercept = np.polyfit(predicted, table.f_hz**2, 1, w=1.0 / (2.0 * table.f_hz * table.f_std_hz))
    return float(slope / intercept), spread_hz
