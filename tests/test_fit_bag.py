"""`mows fit BAG`: ring-downs recorded in a driver-like MCAP bag, fitted offline."""

import csv
import math

import numpy as np
import pytest

from mows.cli import main as cli
from mows.cli.calibrate_bag import SupplyTimeline
from mows.device import bags
from mows.sim.cycle import simulate_cycle
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

STORE = bags.typestore()
RAW, EXCITATION = "mows_msgs/msg/MagnetometerBlock", "mows_msgs/msg/ExcitationState"
BLOCK = 500


def stamp(seconds):
    Time = STORE.types["builtin_interfaces/msg/Time"]
    whole = math.floor(seconds)
    return Time(sec=int(whole), nanosec=int(round((seconds - whole) * 1e9)))


def header(seconds, frame="mows"):
    return STORE.types["std_msgs/msg/Header"](stamp=stamp(seconds), frame_id=frame)


def block_message(first, fs, samples, saturated):
    Channel = STORE.types["mows_msgs/msg/MagnetometerChannel"]
    channels = [
        Channel(
            frame_id=f"fluxgate_{i}",
            field_t=np.ascontiguousarray(samples[:, i]),
            saturated=np.ascontiguousarray(saturated[:, i]),
        )
        for i in range(2)
    ]
    return STORE.types[RAW](
        header=header(first / fs),
        sequence=first // BLOCK,
        first_sample_index=first,
        sample_rate_hz=fs,
        range_t=1e-5,
        resolution_t=1e-10,
        channels=channels,
    )


def ringdown_message(index, fs, cycle, theta0, frequency):
    return STORE.types[EXCITATION](
        header=header(index / fs),
        phase=3,
        phase_name="RINGDOWN",
        cycle_id=cycle,
        repeat_index=0,
        repeats=1,
        tuning=False,
        coils_on=False,
        coil_current_amplitude_a=np.zeros(2),
        frequency_hz=frequency,
        theta0_rad=theta0,
        planned_duration_s=0.5,
        setup="largest_spacing",
    )


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    """Two simulated cycles streamed as blocks, each ring-down announced at its coil-off sample."""
    scenario = load_scenario()
    device = SimulatedDevice(scenario, np.random.default_rng(9))
    messages, truths = [], []
    for cycle, deg in enumerate((0.0, 60.0), start=1):
        record = simulate_cycle(device, math.radians(deg), scenario.excitation.amplitude_a)
        fs = record.sample_rate_hz
        first = record.block.samples.first_sample_index
        off = first + record.coil_off_index
        messages.append(
            bags.BagMessage(
                "/mows/excitation",
                EXCITATION,
                int(off / fs * 1e9),
                ringdown_message(off, fs, cycle, record.theta0_rad, record.frequency_hz),
            )
        )
        for start in range(0, len(record.samples_t), BLOCK):
            index = first + start
            messages.append(
                bags.BagMessage(
                    "/mows/raw",
                    RAW,
                    int(index / fs * 1e9),
                    block_message(
                        index, fs, record.samples_t[start : start + BLOCK], record.saturated[start : start + BLOCK]
                    ),
                )
            )
        truths.append(record.ringdown_frequency_hz(0.497))
    messages.sort(key=lambda m: m.timestamp_ns)
    path = bags.write_bag(tmp_path_factory.mktemp("bag") / "recorded", messages)
    return path, truths


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
