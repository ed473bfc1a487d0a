"""`mows calibrate --table`: the points written and read back, θmax only where a fit measured it."""

import math

import numpy as np

from mows.estimate.calibration.constants import CalibrationPoint
from mows.lab.data.calibration_table import read_points, write_points


def test_a_swing_no_fit_measured_is_written_by_the_stop_rule_and_read_back_as_unknown(tmp_path):
    measured = CalibrationPoint("helmholtz", 1.0, 0.0, 125.0, 1e-3, math.radians(23.9), 1.8, 0.5, 0.003)
    deflected = CalibrationPoint("helmholtz", 2.0, math.pi / 2, 121.0, 1e-3, math.nan, 1.8, 0.5, 0.003, 0.2)
    path = tmp_path / "points.csv"
    write_points(path, [measured, deflected], "helmholtz", math.radians(24.0))
    rows = open(path).read().splitlines()
    header = rows[0].split(",")
    written = [float(row.split(",")[header.index("amplitude_deg")]) for row in rows[1:]]
    # released at the stop about its rest offset, decayed over the 3 ms to the fit's first sample
    np.testing.assert_allclose(written, [23.9, (24.0 - math.degrees(0.2)) * math.exp(-1.8 * 0.003)])
    back = read_points(path, "helmholtz")
    assert math.isclose(back[0].amplitude_rad, math.radians(23.9)) and math.isnan(back[1].amplitude_rad)
