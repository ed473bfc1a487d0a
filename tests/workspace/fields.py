"""Sweeps in a known field for the workspace tests: by default two point dipoles outside the
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
STD = (FIELD_STD_T, FIELD_STD_T, GRADIENT_STD_T_PER_M, GRADIENT_STD_T_PER_M, GRADIENT_STD_T_PER_M)


_FIELDS = {}  # B, G and H of a source at a count's positions: a Biot–Savart Hessian takes a while


def _fields(source, count):
    key = (id(source), count)
    if key not in _FIELDS:
        positions = boundary_positions(count, RADIUS_M)
        _FIELDS[key] = (source, positions, source.field_t(positions), source.gradient_t_per_m(positions))
        _FIELDS[key] += (source.hessian_t_per_m2(positions),)
    return _FIELDS[key][1:]


def sweeps(count, rng, gravity=(0.0, 0.0, -9.80665), source=SOURCE, std=STD):
    """Sweep-like observations: in-plane B (with gravity and the lever's curvature) and G, of
    σ ``std`` (Bx, By, Gxx, Gxy, Gyy), at ``count`` positions on the ball's boundary."""
    positions, *fields = _fields(source, count)
    std = np.asarray(std, float)
    observations = []
    for group, (position, field, gradient, hessian) in enumerate(zip(positions, *fields)):
        plane = random_rotation(rng)[:2]
        readout = plane_readout(plane, PAPER_PROBE.lever_m, gravity_field_t(PAPER_PROBE, gravity))
        exact = (
            readout.field @ field
            + np.einsum("pij,ij->p", readout.gradient, gradient)
            + np.einsum("pijk,ijk->p", readout.hessian, hessian)
            + readout.offset
        )
        values = exact + rng.normal(size=5) * std
        observations.append(
            Observation(position, plane, values, np.diag(std**2), readout, group, ("bx", "by", "gxx", "gxy", "gyy"))
        )
    return observations
