"""A table's numbers held against its probes' scale, before any fit: ring-down frequencies near
each probe's f00, and a reference field a ring-down of the probe could be measured in (Eq. 6).
What fails is a column in the wrong unit (kHz, mT given as T) or another probe's table; each
refusal is a ValueError naming the column, the rows and the likely unit.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from numpy.typing import ArrayLike

from mows.lab.data.probe_rows import ProbeSet
from mows.lab.data.table import FIELD, GRADIENT, PROBE, MeasurementTable, rows_text
from mows.physics.frequency import field_spring_nm_per_rad, frequency_shift_hz, gradient_spring_nm_per_rad
from mows.physics.probe import Probe

#: Ring-down frequencies this far (a factor) from the probe's f00 are no ring-downs of it: a
#: unit error (kHz) or another probe. The strongest fields of the paper move f by a factor ~2.
FREQUENCY_FACTOR = 10.0


def table_probes(table: MeasurementTable, default: Probe, named: Mapping[int, Probe]) -> Probe:
    """The probe of every row: ``default`` for a table without a probe column (and no file named
    by id), else a ProbeSet; each probe's frequencies checked against its f00."""
    if not table.has(PROBE):
        if named:
            raise ValueError(
                f"--probe ID=FILE given for probe {', '.join(map(str, named))}, but the table has no "
                f"column '{PROBE}' saying which row is which probe"
            )
        check_frequencies(table.columns["f_hz"], default, "f_hz")
        return default
    probes = ProbeSet.for_table(table, default, named)
    index = probes.index(table)
    for k, (i, member) in enumerate(probes.members):
        check_frequencies(table.columns["f_hz"][index == k], member, f"f_hz of probe {i}")
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


def check_reference(table: MeasurementTable, probe: Probe) -> None:
    """ValueError when a row's reference field or gradient is one no ring-down of ``probe`` could
    be measured in: its spring alone, kB = m·|B| or kG = l·m·|G| (Eq. 6), would move f by more
    than FREQUENCY_FACTOR from f00 (k/kM > FREQUENCY_FACTOR²), where check_frequencies has
    found the measured ones. A column in mT or µT given as T, or another bench's reference."""
    springs = {
        "field": (FIELD, probe.moment_am2, "T"),
        "gradient": (GRADIENT, probe.lever_m * probe.moment_am2, "T/m"),
    }
    for what, (names, per_unit, unit) in springs.items():
        given = [table.columns[name] for name in names if table.has(name)]
        if not given:
            continue
        size = np.max(np.abs(given), axis=0)
        bad = np.flatnonzero(per_unit * size / probe.spring_nm_per_rad > FREQUENCY_FACTOR**2 - 1.0)
        if bad.size:
            raise ValueError(
                f"{table.source}: the reference {what} {size[bad[0]]:.4g} {unit} ({rows_text(bad)}) would by "
                f"itself move the frequency more than a factor {FREQUENCY_FACTOR:g} from f00 (Eq. 6): "
                f"a column in m{unit} or µ{unit} given in {unit}?"
            )
    check_reference_scale(table, probe)


#: A predicted spread of frequencies this many times the measurement's noise makes the
#: reference's scale measurable against the ring-downs.
SCALE_EVIDENCE_SIGMAS = 10.0


def check_reference_scale(table: MeasurementTable, probe: Probe) -> None:
    """ValueError when the ring-downs move with the reference a factor FREQUENCY_FACTOR more or
    less than Eq. 6 says they must: the measured f against the published model's f for each
    row's reference (its field and gradient along the probe's axis), fitted as a line, has a
    slope near ±1 for a reference in tesla; near 10⁻³ for one in mT given as T. Judged only
    where the reference's predicted spread stands SCALE_EVIDENCE_SIGMAS above the noise."""
    derived = table.derived_columns()
    if "b_along_t" not in derived and "g_t_per_m" not in derived:
        return
    spring = field_spring_nm_per_rad(probe.moment_am2, derived.get("b_along_t", 0.0)) + gradient_spring_nm_per_rad(
        probe.moment_am2, probe.lever_m, derived.get("g_t_per_m", 0.0)
    )
    predicted = frequency_shift_hz(probe.f00_hz, probe.spring_nm_per_rad, spring) * np.ones(table.n)
    usable = np.isfinite(predicted)
    noise_hz = float(np.median(table.f_std_hz))
    if usable.sum() < 3 or np.std(predicted[usable]) < SCALE_EVIDENCE_SIGMAS * noise_hz:
        return
    slope = np.polyfit(predicted[usable], table.f_hz[usable], 1, w=1.0 / table.f_std_hz[usable])[0]
    if not 1.0 / FREQUENCY_FACTOR <= abs(slope) <= FREQUENCY_FACTOR:
        raise ValueError(
            f"{table.source}: the ring-downs move {abs(slope):.3g} times as much as the reference field and "
            f"gradient say they must (Eq. 6, spread {np.std(predicted[usable]):.3g} Hz predicted): "
            "the reference in mT or µT given in T, or another bench's?"
        )
