"""`mows fit BAG`: ring-downs recorded in a driver-like MCAP bag, fitted offline."""

import csv

import pytest

from mows.cli import main as cli
from mows.sim.scenario import load_scenario
from recorded_bags import record_cycles


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    """Two simulated cycles streamed as blocks, each ring-down announced at its coil-off sample."""
    path, records = record_cycles(tmp_path_factory.mktemp("bag") / "recorded", load_scenario(), (0.0, 60.0), 9)
    return path, [record.ringdown_frequency_hz(0.497) for record in records]


def test_every_recorded_ringdown_is_fitted_and_tabled(bag, tmp_path, capsys):
    path, truths = bag
    table = tmp_path / "fits.csv"
    assert cli.main(["fit", str(path), "--csv", str(table)]) == 0
    assert "2 of 2 ring-downs fitted" in capsys.readouterr().out
    rows = list(csv.DictReader(open(table)))
    assert [float(r["theta0_deg"]) for r in rows] == pytest.approx([0.0, 60.0])
    for row, truth in zip(rows, truths):
        assert abs(float(row["f_hz"]) - truth) < 4 * float(row["f_std_hz"])
        assert float(row["amplitude_deg"]) == pytest.approx(24.0, abs=3.0)


def test_a_missing_bag_is_a_clear_error(tmp_path, capsys):
    assert cli.main(["fit", str(tmp_path / "nothing")]) == 2
    assert "nothing" in capsys.readouterr().err
