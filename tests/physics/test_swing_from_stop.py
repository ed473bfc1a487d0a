"""The swing a ring-down starts its fit with, released at the housing stop: one definition
(:func:`mows.physics.ringdown_average.swing_from_stop_rad`) on every path that writes it.

Requirement: where a fit did not determine θmax, the swing written for it is the swing about
its rest angle at the fit's first sample: released at rest at the stop, the lever swings
stop − |θs − θ0| about θs and decays as e^(−δt) until the fit starts. The calibration table
and the simulated tables write it as the sweep record does. The truth here is a second
integrator's: the damped pendulum about θs (Eq. S1 linearised) integrated by scipy's
solve_ivp from the stop, its envelope √(x² + ((ẋ + δx)/ωd)²) at the fit's first sample.
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from mows.estimate.calibration.constants import CalibrationPoint
from mows.lab.data.calibration_table import write_points
from mows.lab.data.synthetic import _start_amplitudes_rad
from mows.physics.probe import PAPER_PROBE
from mows.sweep.record import SweepPoint, SweepRecord

F_HZ = 112.4
STOP_RAD = PAPER_PROBE.theta_stop_rad
# (θ0, rest offset θs − θ0, δ, the fit's first sample after the switch-off): offsets both ways,
# and starts late enough that a swing left undecayed is off by 9–40 %.
RINGDOWNS = [(0.0, 0.05, 1.8, 0.05), (1.0, -0.1, 2.5, 0.2), (2.0, 0.0, 1.2, 0.1)]


def swing_at_rad(rest_rad: float, damping_per_s: float, t_s: float) -> float:
    """The envelope of the swing about θs at ``t_s``, the lever released at rest at the stop on
    the side of its deflection."""
    omega0 = 2 * math.pi * F_HZ
    omega_d = math.sqrt(omega0**2 - damping_per_s**2)
    x0 = math.copysign(STOP_RAD, rest_rad) - rest_rad

    def pendulum(_, y):
        return [y[1], -2 * damping_per_s * y[1] - omega0**2 * y[0]]

    x, v = solve_ivp(pendulum, (0.0, t_s), [x0, 0.0], method="DOP853", rtol=1e-11, atol=1e-14).y[:, -1]
    return math.hypot(x, (v + damping_per_s * x) / omega_d)


TRUTH = np.array([swing_at_rad(rest, d, t) for _, rest, d, t in RINGDOWNS])


def sweep_points() -> list[SweepPoint]:
    """The ring-downs as a sweep's points, θmax not determined, the rest offset determined."""
    return [
        SweepPoint(
            th,
            F_HZ,
            1e-3,
            0.0,
            1e-3,
            math.nan,
            d,
            0.5,
            0.0,
            rest_offset_rad=rest,
            rest_offset_std_rad=1e-4,
            start_offset_s=t,
        )
        for th, rest, d, t in RINGDOWNS
    ]


def test_the_sweep_records_start_swing_is_the_released_swing_at_the_fits_start():
    start, _ = SweepRecord(sweep_points()).fitted_start_amplitudes_rad(STOP_RAD)
    np.testing.assert_allclose(start, TRUTH, rtol=1e-4)


def test_the_calibration_table_writes_the_released_swing_at_the_fits_start(tmp_path):
    points = [CalibrationPoint("field", 0.0, th, F_HZ, 1e-3, math.nan, d, 0.5, t, rest) for th, rest, d, t in RINGDOWNS]
    path = tmp_path / "calibration.csv"
    write_points(path, points, "field", STOP_RAD)
    written = np.radians(np.genfromtxt(path, delimiter=",", names=True, comments=None)["amplitude_deg"])
    np.testing.assert_allclose(written, TRUTH, rtol=1e-4)
    undecayed = STOP_RAD - np.abs([rest for _, rest, _, _ in RINGDOWNS])
    assert np.all(np.abs(written - undecayed) > 0.05 * undecayed)  # the decay is no rounding


def test_the_simulated_tables_write_the_released_swing_at_the_fits_start():
    """Two orientations decompose nothing: θs = 0 for each, as the simulated tables then take it."""
    points = [dataclasses.replace(p, rest_offset_rad=math.nan, rest_offset_std_rad=math.nan) for p in sweep_points()]
    (start,) = _start_amplitudes_rad([SweepRecord(points)], PAPER_PROBE)
    truth = [swing_at_rad(0.0, d, t) for _, _, d, t in RINGDOWNS]
    np.testing.assert_allclose(start, truth, rtol=1e-4)


@pytest.mark.parametrize("rest_rad", [0.5, -0.5])
def test_no_swing_where_the_stop_lies_inside_the_deflection(rest_rad):
    start, _ = SweepRecord(
        [
            SweepPoint(
                0.0, F_HZ, 1e-3, 0.0, 1e-3, math.nan, 1.8, 0.5, 0.0, rest_offset_rad=rest_rad, rest_offset_std_rad=1e-4
            )
        ]
    ).fitted_start_amplitudes_rad(STOP_RAD)
    assert np.isnan(start).all()
