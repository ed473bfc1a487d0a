"""Sweeps in a closed-form field for the workspace tests: two point dipoles outside the
workspace (mows.physics.sources), read exactly at each pose with Gaussian noise of the stated
covariance, so that the fit is tested against the physics, not against itself."""

import numpy as np

from mows.physics.field import PointDipole
from mows.physics.probe import PAPER_PROBE
from mows.workspace.design import boundary_positions, random_rotation
from mows.workspace.observations import Observation, gravity_field_t, plane_readout

RADIUS_M = 0.025
# ~1.5 mT and 10 mT/m over the ball, from 0.35 m away: degree 6 holds it to below the noise
SOURCE = PointDipole([240.0, -80.0, 160.0], [0.28, 0.14, -0.14]) + PointDipole(
    [-40.0, 200.0, 80.0], [-0.14, 0.28, 0.14]
)
FIELD_STD_T = 50e-9
GRADIENT_STD_T_PER_M = 20e-6


def sweeps(count, rng, gravity=(0.0, 0.0, -9.80665)):
    """Sweep-like observations: in-plane B (with gravity and the lever's curvature) and G."""
    observations = []
    for group, position in enumerate(boundary_positions(count, RADIUS_M)):
        plane = random_rotation(rng)[:2]
        readout = plane_readout(plane, PAPER_PROBE.lever_m, gravity_field_t(PAPER_PROBE, gravity))
        exact = (
            readout.field @ SOURCE.field_t(position)
            + np.einsum("pij,ij->p", readout.gradient, SOURCE.gradient_t_per_m(position))
            + np.einsum("pijk,ijk->p", readout.hessian, SOURCE.hessian_t_per_m2(position))
            + readout.offset
        )
        std = np.array([FIELD_STD_T] * 2 + [GRADIENT_STD_T_PER_M] * 3)
        cov = np.diag(std**2)
        values = exact + rng.normal(size=5) * std
        observations.append(
            Observation(position, plane, values, cov, readout, group, ("bx", "by", "gxx", "gxy", "gyy"))
        )
    return observations
