"""How a recorded sweep's start swings are found: from the sweep's own field where one static
field describes its ring-downs (χ²/dof ≤ MAX_SWEEP_CHI2_DOF), else from each fit alone.

The ring-downs are the full potential's frequencies in a uniform field (the truth), with σ wide
enough for the finite-amplitude term the synthetic points leave out; the sweep no field
describes has ±50 mHz of scatter on top, 10 σ."""

import math

import numpy as np

from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.record import MAX_SWEEP_CHI2_DOF, SweepPoint, SweepRecord

THETA0 = np.radians(np.arange(0.0, 360.0, 30.0))
STD_HZ = 5e-3
FIELD = UniformField((200e-6, 120e-6, 0.0))


def record(scatter_hz: float) -> SweepRecord:
    noise = np.random.default_rng(3).standard_normal(THETA0.size)
    points = []
    for theta0, extra in zip(THETA0, scatter_hz * noise):
        f = ArcPotential.from_source(P, FIELD, Pose(theta0_rad=float(theta0))).frequency_hz() + extra
        points.append(SweepPoint(float(theta0), f, STD_HZ, f - P.f00_hz, STD_HZ, math.nan, P.damping_per_s, 0.5, 0.0))
    return SweepRecord(points)


def test_a_sweep_one_field_describes_gives_each_rest_angle_from_its_field():
    sweep = record(0.0)
    decomposition = sweep.decompose(P, P.f00_hz)
    assert decomposition.ok and decomposition.chi2_dof <= MAX_SWEEP_CHI2_DOF
    start, notes = sweep.start_swings_rad(P)
    assert notes[0].startswith("start swings: the stop less the rest angle in the sweep's field")
    np.testing.assert_array_equal(start, sweep.start_amplitudes_rad(decomposition, P))
    # the rest angle differs from orientation to orientation: not the stop everywhere
    assert np.ptp(start) > math.radians(0.1)


def test_a_sweep_no_field_describes_takes_each_fit_alone():
    sweep = record(10.0 * STD_HZ)
    decomposition = sweep.decompose(P, P.f00_hz)
    assert not decomposition.ok or decomposition.chi2_dof > MAX_SWEEP_CHI2_DOF
    start, notes = sweep.start_swings_rad(P)
    fitted, fitted_notes = sweep.fitted_start_amplitudes_rad(P.theta_stop_rad)
    np.testing.assert_array_equal(start, fitted)
    assert notes == fitted_notes and not any("sweep's field" in note for note in notes)
