"""Synthetic tables shared by the lab's tests."""

import math

import numpy as np

from mows.lab.data import synthetic
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE


def rotation_table(source, seed: int = 0, truth_amplitude_deg: float | None = None, sweeps: int = 2, **options):
    """``sweeps`` rotation sweeps every 15° of the paper's probe in ``source``; with
    ``truth_amplitude_deg`` the true frequencies are those of ring-downs of that amplitude
    (whatever amplitude the table states). ``options`` go to :func:`synthetic.synthesize`."""
    sweep = synthetic.rotation_sweeps(15.0, sweeps)
    theta0 = sweep.pop("theta0_deg")
    if truth_amplitude_deg is not None:
        amplitude_rad = math.radians(truth_amplitude_deg)
        options["truth_hz"] = synthetic.true_frequency_hz(PAPER_PROBE, source, np.radians(theta0), amplitude_rad)
    return synthetic.synthesize(PAPER_PROBE, source, theta0, np.random.default_rng(seed), **options, **sweep)


def tilted_table(sweeps: int = 2, **options):
    """A uniform field with the rotation plane tilted by 1°, so that gravity is the missing effect."""
    gravity = Pose.tilted(math.radians(1.0)).gravity_m_per_s2
    return rotation_table(UniformField((2e-5, -1e-5, -4e-5)), gravity_m_per_s2=gravity, sweeps=sweeps, **options)
