"""The lab refuses what no bench produces and never the physics it is for (mows.lab.data.scale).

Requirements: a weak field on a tilted plane, where gravity's torque nearly cancels the field's,
makes the ring-downs move 1/12.7 as much as Eq. 6 says: that is physics, so the table goes on
with a note. A reference in mT, gauss or µT given as T moves them 10⁻³, 10⁻⁴ or 10⁻⁶ as much:
refused with the unit, unless the user says to trust it. Several probes in one table are
recognised as such: with the column ``probe`` each probe is judged by itself, and without it the
rows of one configuration that ring several Hz apart are refused as several probes, not as a unit.
Truths from exact sources and the exact potential (mows.lab.data.synthetic).
"""

import dataclasses
import math

import numpy as np
import pytest

from mows.cli.main import main
from mows.lab.data import synthetic
from mows.lab.data.probe_rows import ProbeSet
from mows.lab.data.scale import check_reference, table_probes
from mows.lab.data.table import FIELD, GRADIENT, PROBE
from mows.physics.pose import STANDARD_GRAVITY_M_PER_S2
from mows.physics.probe import PAPER_PROBE
from mows.physics.sources import UniformField

PROBE_ = PAPER_PROBE
WEAK_T = 2e-5  # along x
RESPONSE = 1.0 / 12.7  # what gravity leaves of the field's spring
STD_HZ = 1e-3


def _gravity_cancelling(response: float) -> tuple[float, float, float]:
    """Gravity on a plane tilted so that its in-plane part, along −x, acts as the field
    −(1 − response)·B: a·g·l·sin t = (1 − response)·m·B."""
    sin_tilt = (
        (1.0 - response)
        * WEAK_T
        * PROBE_.moment_am2
        / (PROBE_.magnet_mass_kg * STANDARD_GRAVITY_M_PER_S2 * PROBE_.lever_m)
    )
    g = STANDARD_GRAVITY_M_PER_S2
    return (-g * sin_tilt, 0.0, -g * math.sqrt(1.0 - sin_tilt**2))


def _table(gravity=(0.0, 0.0, -STANDARD_GRAVITY_M_PER_S2), field_t=WEAK_T, probe=PROBE_, seed=0):
    sweep = synthetic.rotation_sweeps(30.0, 2)
    theta0 = sweep.pop("theta0_deg")
    return synthetic.synthesize(
        probe,
        UniformField((field_t, 0.0, 0.0)),
        theta0,
        np.random.default_rng(seed),
        STD_HZ,
        2.0,
        gravity_m_per_s2=gravity,
        **sweep,
    )


def _scaled(table, factor):
    names = [name for name in (*FIELD, *GRADIENT) if table.has(name)]
    return table.with_columns(**{name: table.columns[name] * factor for name in names})


def test_gravity_against_a_weak_field_is_physics_and_the_table_goes_on():
    table = _table(_gravity_cancelling(RESPONSE))
    checked = check_reference(table, ProbeSet.one(PROBE_))
    (note,) = [note for note in checked.notes if "times as much" in note]
    response = float(note.split("move ")[1].split(" times")[0])
    # the slope's σ is σf/(spread·√n) = 0.004 on 24 rows: 3σ is 15 % of it
    assert response == pytest.approx(RESPONSE, rel=0.15), note
    assert "physics the model must find" in note


def test_a_response_near_one_says_nothing():
    table = _table()
    assert check_reference(table, ProbeSet.one(PROBE_)) is table


@pytest.mark.parametrize("factor, unit, field_t", [(1e3, "mT", 4e-4), (1e4, "gauss", 4e-5), (1e6, "µT", 1e-6)])
def test_a_reference_in_another_unit_is_refused_with_the_unit_unless_trusted(factor, unit, field_t):
    """Fields that stay below 1.5 T written in the wrong unit: the per-row check (a spring 100
    times kM) lets them through, the response refuses them."""
    table = _table(field_t=field_t)
    wrong = _scaled(table, factor)  # the numbers of the unit, read as tesla
    with pytest.raises(
        ValueError, match=f"a factor 10\\^{round(math.log10(factor))} is a unit, the reference in {unit}"
    ):
        check_reference(wrong, ProbeSet.one(PROBE_))
    trusted = check_reference(wrong, ProbeSet.one(PROBE_), trust_scale=True)
    assert any("times as much" in note for note in trusted.notes)


def test_a_factor_that_is_no_unit_is_a_note():
    table = _scaled(_table(field_t=4e-4), 30.0)
    checked = check_reference(table, ProbeSet.one(PROBE_))
    assert any("times as much" in note for note in checked.notes), checked.notes


def _two_probes(with_column: bool):
    """Probes 4 Hz apart (another spring), one row each per orientation and sweep, 0.4 mT."""
    other = dataclasses.replace(PROBE_, spring_nm_per_rad=PROBE_.spring_nm_per_rad * 1.072)
    tables = [_table(field_t=4e-4, probe=p, seed=i) for i, p in enumerate((PROBE_, other))]
    columns = {name: np.concatenate([t.columns[name] for t in tables]) for name in tables[0].columns}
    if with_column:
        columns[PROBE] = np.repeat([0.0, 1.0], len(tables[0]))
    return dataclasses.replace(tables[0], columns=columns)


def test_several_probes_without_their_column_are_refused_as_such():
    with pytest.raises(ValueError, match="ring at 2 frequencies .* several probes in one table"):
        table_probes(_two_probes(False), PROBE_, {})


def test_several_probes_with_their_column_are_judged_each_by_itself():
    table = _two_probes(True)
    probes = table_probes(table, PROBE_, {})
    assert isinstance(probes, ProbeSet)
    assert check_reference(table, probes) is table  # each probe moves as Eq. 6 says: nothing to note
    shifted = table.with_columns(f_hz=np.where(table.columns[PROBE] == 1, table.f_hz - 3.0, table.f_hz))
    assert check_reference(shifted, probes) is shifted  # an offset between the probes is their f00s


def test_the_command_line_refuses_a_unit_and_takes_it_with_trust_reference(tmp_path, capsys):
    path = tmp_path / "sweep.csv"
    _scaled(_table(field_t=4e-4), 1e3).to_csv(path)
    assert main(["lab", "compare", str(path)]) == 2
    assert "the reference in mT given in T? (--trust-reference takes it as given)" in capsys.readouterr().err
    assert main(["lab", "compare", str(path), "--trust-reference", "--no-cv"]) == 0
    out = capsys.readouterr().out
    assert "note: the ring-downs move 0.000999 times as much" in out and "verdict:" in out
