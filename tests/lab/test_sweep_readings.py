"""A recorded sweep read both ways from the f00 its ring-downs carry, and its lab table in the
reference it was taken in."""

import math

import numpy as np

from mows.lab.data.readers import read_sweep
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.record import SweepPoint, SweepRecord

FIELD_T = (200e-6, 120e-6, 0.0)
STD_HZ = 5e-3
F00_OFFSET_HZ = 0.01  # the estimator's f00, off the probe file's


def test_a_sweep_is_read_from_its_own_f00_both_ways_into_its_table():
    source = UniformField(FIELD_T)
    points = []
    for theta0 in np.radians(np.arange(0.0, 360.0, 30.0)):
        f = ArcPotential.from_source(P, source, Pose(theta0_rad=float(theta0))).frequency_hz()
        shift = f - (P.f00_hz + F00_OFFSET_HZ)
        points.append(SweepPoint(float(theta0), f, STD_HZ, shift, STD_HZ, math.nan, P.damping_per_s, 0.5, 0.0))
    record = SweepRecord(points)
    readings = read_sweep(record, source, P)
    assert math.isclose(readings.f00_hz, P.f00_hz + F00_OFFSET_HZ, rel_tol=1e-12)
    for decomposition, model in ((readings.first_principles, "first_principles"), (readings.published, "published")):
        direct = record.decompose(P, P.f00_hz + F00_OFFSET_HZ, model=model)
        assert decomposition.ok and decomposition.model == model
        np.testing.assert_allclose(decomposition.parameters, direct.parameters, rtol=1e-9)
    assert len(readings.table) == len(points)
    np.testing.assert_allclose(readings.table.field_t, np.tile(FIELD_T, (len(points), 1)))
