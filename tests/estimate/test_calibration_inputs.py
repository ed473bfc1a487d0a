"""What a calibration leaves out or fills in, it says: a θmax the fits did not determine is
read from a table as not measured, as ``mows calibrate --table`` flags it (the calibration then
takes the start swing from the stop), and a ring-down without a finite frequency is left out
by number and reason."""

import dataclasses
import math
import pathlib

import numpy as np
import pytest

from mows.estimate.calibration.constants import KnownConstants
from mows.estimate.calibration.fit_constants import calibrate_probe
from mows.lab.data.calibration_table import read_points, write_points
from mows.physics.probe import PAPER_PROBE
from mows.sim.scenario import load_scenario
from mows.sweep.calibration.schedule import scenario_wirings

TABLE = pathlib.Path(__file__).parent / "data" / "calibration_36.csv"
UNDETERMINED = (3, 7)  # rows whose θmax the fit did not determine


@pytest.fixture(scope="module")
def wirings():
    return scenario_wirings(load_scenario("calibration"), load_scenario("calibration_gradient"))


def with_amplitudes(path, tmp_path, name, value):
    lines = path.read_text().splitlines()
    column = lines[0].split(",").index("amplitude_deg")
    for row in UNDETERMINED:
        cells = lines[row + 1].split(",")
        cells[column] = value
        lines[row + 1] = ",".join(cells)
    out = tmp_path / name
    out.write_text("\n".join(lines) + "\n")
    return out


def test_a_nan_theta_max_is_read_as_not_measured_like_a_flagged_one(tmp_path, wirings):
    undetermined = read_points(with_amplitudes(TABLE, tmp_path, "nan.csv", "nan"), "helmholtz")
    assert [i for i, p in enumerate(undetermined) if math.isnan(p.amplitude_rad)] == list(UNDETERMINED)
    known = KnownConstants.of(PAPER_PROBE)
    calibration = calibrate_probe(undetermined, wirings, known, "helmholtz")
    written = tmp_path / "written.csv"
    write_points(written, undetermined, "helmholtz", PAPER_PROBE.theta_stop_rad)
    again = read_points(written, "helmholtz")
    assert [math.isnan(p.amplitude_rad) for p in again] == [math.isnan(p.amplitude_rad) for p in undetermined]
    np.testing.assert_allclose(
        calibrate_probe(again, wirings, known, "helmholtz").values, calibration.values, rtol=1e-12
    )


def test_a_ring_down_without_a_finite_frequency_is_left_out_by_number(wirings):
    points = read_points(TABLE, "helmholtz")
    points[4] = dataclasses.replace(points[4], frequency_hz=math.nan)
    calibration = calibrate_probe(points, wirings, KnownConstants.of(PAPER_PROBE), "helmholtz")
    (note,) = [n for n in calibration.notes if "left out" in n]
    assert note.startswith("ring-down 5 (+1.0000 A, θ0 0.0°) left out") and "not a finite number" in note
    assert calibration.n_points == len(points) - 1
