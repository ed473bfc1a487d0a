"""`mows fit BAG`: ring-downs recorded in a driver-like MCAP bag, fitted offline."""

import csv

import pytest

from mows.cli import main as cli
from mows.cli.calibrate_bag import SupplyTimeline
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


def test_calibrating_a_bag_without_the_supply_current_is_refused_in_one_line(bag, tmp_path, capsys):
    # Recorded before the driver published mows/supply: no ring-down's applied field is known.
    path, _ = bag
    probe = tmp_path / "probe.yaml"
    assert cli.main(["calibrate", str(path), "-o", str(probe)]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "no supply current" in error and "mows_msgs/msg/SupplyState" in error
    assert not probe.exists()


def test_a_ring_down_has_a_supply_current_only_if_the_supply_held_steady_over_it():
    timeline = SupplyTimeline((0, 100, 200, 400), (1.0, 1.0, 2.0, 2.0), (True, False, True, False))
    assert timeline.steady_current_a(100, 150) == 1.0
    assert timeline.steady_current_a(500, 900) == 2.0
    assert timeline.steady_current_a(50, 90) is None  # still ramping
    assert timeline.steady_current_a(150, 250) is None  # a ramp began within it
    assert timeline.steady_current_a(-10, 0) is None  # before the supply was set
    # a "ramp" to the present current starts and ends at one sample: the later state holds
    assert SupplyTimeline((0, 0), (0.0, 0.0), (True, False)).steady_current_a(10, 20) == 0.0
