"""`mows fit BAG`: ring-downs recorded in a driver-like MCAP bag, fitted offline."""

import csv

import numpy as np
import pytest

from mows.cli import main as cli
from mows.cli.calibrate_bag import SupplyTimeline
from mows.device.recording.bags import read_bag
from mows.estimate.probe_set import ProbeEntry
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions
from mows.estimate.segments import SegmentAssembler, block_from_message, fit_segment, window_from_message
from mows.physics.fluxgate import FluxgatePair
from mows.physics.probe import PAPER_PROBE
from mows.sim.scenario import load_scenario
from mows.sweep.record import sweep_numbers
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


def test_one_probe_is_fitted_as_before_the_estimators_stream_core_took_it(bag, tmp_path, capsys):
    """The stream core (mows.estimate.stream) gives, for one probe, bit for bit the fits of the
    segments assembled and fitted directly with the lever-aware model of the paper's pair."""
    path, _ = bag
    assembler, segments = SegmentAssembler(buffer_s=60.0), []
    for item in read_bag(path, topics=["/mows/raw", "/mows/excitation"]):
        if item.topic == "/mows/excitation":
            segments += assembler.announce(window_from_message(item.message))
        else:
            segments += assembler.add_block(block_from_message(item.message))
    pair = FluxgatePair.paper()
    own = ProbeEntry(0, PAPER_PROBE, PAPER_PROBE.f00_hz)
    options = FitOptions(theta_stop_rad=PAPER_PROBE.theta_stop_rad)
    direct = [
        fit_segment(
            s,
            [own.line(s.window.theta0_rad, pair, "difference", s.window.excitation_frequency_hz)],
            COIL_OFF_SKIP_S,
            options,
        )[0]
        for s in segments
    ]
    table = tmp_path / "fits.csv"
    assert cli.main(["fit", str(path), "--csv", str(table)]) == 0
    rows = list(csv.DictReader(open(table)))
    assert [(float(r["f_hz"]), float(r["f_std_hz"])) for r in rows] == [
        (fit.frequency_hz, fit.frequency_std_hz) for fit in direct
    ]
    assert "probe" not in rows[0]


def test_the_table_numbers_its_sweeps_and_joins_a_temperature_log(tmp_path, capsys):
    """Three ring-downs at 0°, 60°, 0°: the third starts the second sweep (a sweep measures each
    orientation once). A logger's linear ramp, 290 K + 0.01 K/s on the device clock, sampled
    every 0.5 s, is each ring-down's temperature at its coil-off, to rounding."""
    path, records = record_cycles(tmp_path / "recorded", load_scenario(), (0.0, 60.0, 0.0), 5)
    coil_off_s = [(r.block.samples.first_sample_index + r.coil_off_index) / r.sample_rate_hz for r in records]
    log = tmp_path / "temperature.csv"
    times = [0.5 * k for k in range(int(2 * coil_off_s[-1]) + 3)]
    log.write_text("t_s,temperature_k\n" + "".join(f"{t},{290.0 + 0.01 * t}\n" for t in times))
    table = tmp_path / "fits.csv"
    assert cli.main(["fit", str(path), "--csv", str(table), "--temperature-log", str(log)]) == 0
    rows = list(csv.DictReader(open(table)))
    assert [float(r["sweep"]) for r in rows] == [0.0, 0.0, 1.0]
    assert [float(r["temperature_k"]) for r in rows] == pytest.approx([290.0 + 0.01 * t for t in coil_off_s], abs=1e-9)
    short = tmp_path / "short.csv"
    short.write_text("t_s,temperature_k\n0,290\n0.1,290.001\n")
    assert cli.main(["fit", str(path), "--csv", str(tmp_path / "other.csv"), "--temperature-log", str(short)]) == 2
    error = capsys.readouterr().err.strip().splitlines()[-1]
    assert "temperature log" in error and "the log spans t_s 0 … 0.1 s" in error, error
    assert not (tmp_path / "other.csv").exists()


def test_a_sweep_measures_each_orientation_once():
    degrees = [0.0, 30.0, 60.0, 0.0, 30.0, 60.0, 360.0, 90.0]  # 360° is 0° again
    assert sweep_numbers(np.radians(degrees)).tolist() == [0, 0, 0, 1, 1, 1, 2, 2]
