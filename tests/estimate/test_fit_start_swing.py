"""`mows fit --csv` in a strong field: every ring-down's start swing, as the CSV's amplitude_deg.

Requirement: each ring-down starts at the housing stop, so its swing about the rest angle is
the stop less the rest deflection |θs − θ0|; the table holds that swing within 1° of the
simulator's first swing, and never a value ≤ 0 or NaN. In 3.4 mT along x the deflection is 0
at θ0 = 0° and 11° at 90°: the swings are ~24° and ~13°. Single fits there rarely determine
θmax (its σ is ~0.35° and more), and a pool of their θmax + |ε| by inverse variance is led by
the few fits that sit in a wrong minimum with a small σ.
"""

import csv
import math

import numpy as np
import pytest

from mows.cli import main as cli
from mows.physics.field import UniformField, helmholtz_pair
from mows.sim.scenario import load_scenario
from mows.sim.sections import Environment
from mows.sweep.record import SweepPoint, SweepRecord
from recorded_bags import record_cycles

ANGLES_DEG = (0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0, 0.0, 90.0)


def strong_helmholtz():
    pair = helmholtz_pair((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), radius_m=0.105, turns=200, current_a=2.0)
    return load_scenario("helmholtz").replace(
        environment=Environment(sources=(UniformField((16e-6, 12e-6, -43.6e-6)), pair))
    )


@pytest.mark.slow
def test_the_table_holds_each_ring_downs_start_swing_in_a_strong_field(tmp_path, capsys):
    path, records = record_cycles(tmp_path / "bag", strong_helmholtz(), ANGLES_DEG, 3)
    assert abs(math.degrees(records[2].potential.rest_angle_rad())) > 10  # the field deflects at 90°
    table = tmp_path / "fits.csv"
    assert cli.main(["fit", str(path), "--csv", str(table)]) == 0
    assert f"{len(ANGLES_DEG)} of {len(ANGLES_DEG)} ring-downs fitted" in capsys.readouterr().out
    rows = list(csv.DictReader(open(table)))
    assert len(rows) == len(records)
    for row, record in zip(rows, records):
        amplitude_deg = float(row["amplitude_deg"])
        assert math.isfinite(amplitude_deg) and amplitude_deg > 0
        if float(row["theta0_deg"]) in (0.0, 90.0):
            assert abs(amplitude_deg - math.degrees(record.ringdown_amplitude_rad())) <= 1.0, row


def point(amplitude_deg, amplitude_std_deg, rest_deg=math.nan, rest_std_deg=math.nan):
    return SweepPoint(
        0.0,
        112.0,
        1e-3,
        0.0,
        1e-3,
        math.radians(amplitude_deg),
        1.8,
        0.5,
        0.0,
        math.radians(amplitude_std_deg),
        0,
        math.radians(rest_deg),
        math.radians(rest_std_deg),
    )


def test_an_over_confident_wrong_fit_does_not_lead_the_pooled_stop():
    # Five fits that pin θmax and their offset about a 24° stop, one in a wrong minimum with a
    # tiny σ (an inverse-variance mean would put the stop near its 8°), one fit that pinned
    # nothing, one offset beyond the stop and one θmax beyond it.
    good = [point(24.0 - r, 0.2, r, 0.05) for r in (0.5, 1.0, 2.0, 4.0, 8.0)]
    record = SweepRecord(
        good
        + [
            point(8.0, 0.001, 0.3, 0.05),
            point(math.nan, math.nan),
            point(math.nan, math.nan, 30.0, 0.05),
            point(40.0, 0.2),
        ]
    )
    assert math.degrees(record.stop_amplitude_rad()) == pytest.approx(24.0, abs=0.01)
    start, notes = record.fitted_start_amplitudes_rad(math.radians(24.0))
    starts_deg = np.degrees(start)
    np.testing.assert_allclose(starts_deg[:5], [23.5, 23.0, 22.0, 20.0, 16.0], atol=1e-9)
    assert starts_deg[6] == pytest.approx(24.0) and math.isnan(starts_deg[7]) and starts_deg[8] == pytest.approx(24.0)
    assert np.all(starts_deg[np.isfinite(starts_deg)] > 0)
    assert any("beyond the stop" in note for note in notes) and any("neither" in note for note in notes)
