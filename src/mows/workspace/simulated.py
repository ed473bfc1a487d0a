"""Simulated measurements over a workspace: rotation sweeps and Hall-probe points in a known field.

A sweep at a pose is what the probe's physics gives there, decomposed by the sweep's own code:
the field's Taylor expansion to its Hessian at the magnet's rest position (B, G, H of the
source, turned into each orientation's probe frame) and gravity enter the full potential U(θ)
(docs/physics.md §4), whose stiffness gives f = f00·√(k/kM) at each orientation; white noise of
``std_hz`` is added and :func:`mows.sweep.decompose.decompose` (first principles, with the 3θ0
curvature) reports B and G with their covariance. Over the magnet's ±24° swing on a 1.9 mm
lever the next term, ∂³B·l³, is (l/R)³ ≈ 10⁻⁵ of the field for coils R ≈ 10 cm away: below
the noise. A Hall point reads the source's 3D field with Gaussian noise of a fraction of |B|
per component (``HALL_RELATIVE_STD``, a calibrated 3-axis probe).

Robot time: a sweep turns the probe through its orientations, ``ringdowns`` ring-downs each
of one cycle (``CYCLE_S``: drive to the stop, ring down, settle), ``TURN_S`` per turn; a Hall
point needs the arm to move and settle and the probe to average (``HALL_POINT_S``); each pose
costs ``MOVE_S`` of arm motion.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike

from mows.physics.field import FieldSource
from mows.physics.pose import STANDARD_GRAVITY_M_PER_S2, probe_axes
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe
from mows.sweep.decompose import decompose
from mows.sweep.decomposition import Decomposition
from mows.workspace.design import random_rotation
from mows.workspace.observations import Observation, hall_observation, sweep_observation

HALL_RELATIVE_STD = 1e-3
GRAVITY_M_PER_S2 = (0.0, 0.0, -STANDARD_GRAVITY_M_PER_S2)
# Ten orientations leave the decomposition's 7 unknowns (with the curvature) 3 degrees of freedom.
ORIENTATIONS = 10
# σ of one ring-down's frequency: the paper's 0.33 mHz from five ring-downs of 60 periods is
# 0.74 mHz each; rounded up over θ0 (near 90° the signal is at 2f and weaker).
RINGDOWN_STD_HZ = 0.75e-3
RINGDOWNS = 1
CYCLE_S = 1.5
TURN_S = 1.0
MOVE_S = 3.0
HALL_POINT_S = 2.0


def sweep_seconds(orientations: int = ORIENTATIONS, ringdowns: int = RINGDOWNS) -> float:
    """Robot time of one sweep, its move to the pose included (module docstring)."""
    return MOVE_S + orientations * (TURN_S + ringdowns * CYCLE_S)


@dataclasses.dataclass(frozen=True)
class SweepPose:
    """Where a sweep is measured: the magnet's rest position and the rotation plane's rows e1, e2."""

    position_m: np.ndarray
    plane: np.ndarray

    def axes_at(self, theta0_rad: np.ndarray) -> np.ndarray:
        """(n, 3, 3): the probe frame's rows x', y', z' in global coordinates at each θ0."""
        normal = np.cross(self.plane[0], self.plane[1])
        frame = np.stack([self.plane[0], self.plane[1], normal])
        return probe_axes(theta0_rad) @ frame


def random_planes(positions_m: np.ndarray, rng: np.random.Generator) -> list[SweepPose]:
    """A sweep pose at each position, its rotation plane uniform in orientation."""
    return [SweepPose(np.asarray(p, float), random_rotation(rng)[:2]) for p in positions_m]


def ball_points(count: int, radius_m: float, rng: np.random.Generator, centre_m: ArrayLike = (0, 0, 0)) -> np.ndarray:
    """``count`` points uniform in the ball (held-out points of a map)."""
    direction = rng.normal(size=(count, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    return np.asarray(centre_m, float) + radius_m * direction * rng.uniform(0.0, 1.0, (count, 1)) ** (1.0 / 3.0)


def sweep_shifts_hz(source: FieldSource, pose: SweepPose, probe: Probe, theta0_rad: np.ndarray) -> np.ndarray:
    """Noise-free Δf(θ0) of the probe at ``pose`` in ``source``'s field (module docstring)."""
    axes = pose.axes_at(theta0_rad)
    field = axes @ source.field_t(pose.position_m)
    gradient = axes @ source.gradient_t_per_m(pose.position_m) @ np.swapaxes(axes, -1, -2)
    hessian = np.einsum("nia,abc,njb,nkc->nijk", axes, source.hessian_t_per_m2(pose.position_m), axes, axes)
    gravity = axes @ np.asarray(GRAVITY_M_PER_S2)
    potential = ArcPotential.from_local_field(probe, field, gradient, hessian, gravity)
    return probe.f00_hz * (np.sqrt(potential.stiffness_nm_per_rad() / probe.spring_nm_per_rad) - 1.0)


def simulate_sweep(
    source: FieldSource,
    pose: SweepPose,
    probe: Probe,
    rng: np.random.Generator,
    orientations: int = ORIENTATIONS,
    ringdowns: int = RINGDOWNS,
) -> Decomposition:
    """One sweep at ``pose``: equally spaced θ0, noisy Δf (``ringdowns`` averaged at each),
    decomposed (module docstring)."""
    std_hz = RINGDOWN_STD_HZ / math.sqrt(ringdowns)
    theta0 = np.arange(orientations) * (2.0 * math.pi / orientations)
    shift = sweep_shifts_hz(source, pose, probe, theta0) + rng.normal(0.0, std_hz, orientations)
    return decompose(theta0, shift, np.full(orientations, std_hz), probe, probe.f00_hz, curvature=True)


def sweep_observations(decompositions, poses, probe: Probe, first_group: int = 0) -> list[Observation]:
    """Each decomposed sweep as an observation at its (reported) pose."""
    return [
        sweep_observation(d, pose.position_m, pose.plane, probe, first_group + i, GRAVITY_M_PER_S2)
        for i, (d, pose) in enumerate(zip(decompositions, poses))
    ]


def simulate_hall(
    source: FieldSource, positions_m: np.ndarray, rng: np.random.Generator, relative_std: float = HALL_RELATIVE_STD
) -> list[Observation]:
    """A Hall probe's reading at each position: B with σ = ``relative_std``·|B| per component."""
    field = source.field_t(positions_m)
    std = relative_std * np.linalg.norm(field, axis=1)
    noisy = field + rng.normal(size=field.shape) * std[:, None]
    return [hall_observation(p, b, s**2 * np.eye(3), i) for i, (p, b, s) in enumerate(zip(positions_m, noisy, std))]
