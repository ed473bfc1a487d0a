"""The lab's tilted-plane test table: rotation sweeps of 24 orientations in a uniform field with
the rotation plane tilted by 1°, so that gravity is the missing effect (tests/lab)."""

import math

import numpy as np

from mows.lab import synth
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE


def tilted_table(sweeps: int, seed: int = 0):
    sweep = synth.rotation_sweeps(15.0, sweeps)
    theta0 = sweep.pop("theta0_deg")
    return synth.synthesize(
        PAPER_PROBE,
        UniformField((2e-5, -1e-5, -4e-5)),
        theta0,
        np.random.default_rng(seed),
        gravity_m_per_s2=Pose.tilted(math.radians(1.0)).gravity_m_per_s2,
        amplitude_deg=2.0,
        **sweep,
    )
