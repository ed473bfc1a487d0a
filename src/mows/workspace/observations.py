"""What one measurement at one pose says about the field: a linear readout of B, G and H there.

A rotation sweep (:func:`mows.sweep.decompose.decompose`) reports, in its rotation plane spanned
by e1 and e2 (the pose's orientation), the in-plane field (Bx, By) and gradient (Gxx, Gxy, Gyy),
G_ij = ∂B_i/∂x_j, each with its covariance. Two known terms sit in what it reports:

* gravity: the magnet's weight on its lever, −a·g·r(θ), has exactly the form of the field term
  −m(θ)·B with B_g = (a·l/m)·g (docs/physics.md §5, 154 µT for the paper's probe): the sweep's
  field is B + B_g in the plane, and a tilted plane sees part of it;
* the field's curvature over the lever's arc: the sweep's field is B + (l²/4)·∂²B/∂z'² at the
  magnet's rest position, z' = e1 × e2 (:mod:`mows.sweep.shift_model`).

A Hall probe reports the 3D field B. Each observation here is ``values`` = A_B·(B + B_known) +
A_G·G + A_H·H at ``position_m`` with the ``covariance`` of ``values``; the workspace fit
(:mod:`mows.workspace.fit`) turns it into rows of its design. ``group`` is the unit the
cross-validation holds out together (a sweep, or one Hall point).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike

from mows.physics.probe import Probe
from mows.sweep.decomposition import Decomposition

SWEEP_COMPONENTS = ("bx", "by", "gxx", "gxy", "gyy")
HALL_COMPONENTS = ("bx", "by", "bz")


@dataclasses.dataclass(frozen=True)
class Readout:
    """values = field·(B + known_field_t) + gradient·G + hessian·H: ``field`` (k, 3),
    ``gradient`` (k, 3, 3), ``hessian`` (k, 3, 3, 3); ``known_field_t`` (3,), global frame, is
    what the instrument adds to the field it reads (the magnet's weight on a sweep)."""

    field: np.ndarray
    gradient: np.ndarray
    hessian: np.ndarray
    known_field_t: np.ndarray

    @property
    def size(self) -> int:
        return self.field.shape[0]

    @property
    def offset(self) -> np.ndarray:
        return self.field @ self.known_field_t

    def rotated(self, rotation: np.ndarray) -> Readout:
        """The readout of the instrument turned by ``rotation`` (3, 3) about its position: every
        direction it reads along, d, becomes rotation·d."""
        r = np.asarray(rotation, float)
        return Readout(
            self.field @ r.T,
            np.einsum("ai,pij,bj->pab", r, self.gradient, r),
            np.einsum("ai,pijk,bj,ck->pabc", r, self.hessian, r, r),
            self.known_field_t,
        )


@dataclasses.dataclass(frozen=True)
class Observation:
    """One measurement: where (``position_m``; for a sweep the rotation plane's ``plane`` rows
    e1, e2), what it read (``values``, ``covariance``), how (``readout``), ``group`` for the
    cross-validation and ``components`` naming the values."""

    position_m: np.ndarray
    plane: np.ndarray | None
    values: np.ndarray
    covariance: np.ndarray
    readout: Readout
    group: int
    components: tuple[str, ...]

    def __post_init__(self) -> None:
        k = self.values.shape[0]
        if self.covariance.shape != (k, k) or self.readout.size != k or self.position_m.shape != (3,):
            raise ValueError(
                f"observation of {k} values with covariance {self.covariance.shape} and a readout of "
                f"{self.readout.size}, at a position of shape {self.position_m.shape}"
            )
        if not (np.all(np.isfinite(self.values)) and np.all(np.isfinite(self.covariance))):
            raise ValueError("an observation's values and covariance must be finite")
        if np.any(np.linalg.eigvalsh(0.5 * (self.covariance + self.covariance.T)) <= 0):
            raise ValueError("an observation's covariance must be positive definite")


def plane_readout(plane: ArrayLike, lever_m: float, gravity_field_t: ArrayLike) -> Readout:
    """The readout of a sweep in the plane of rows e1, e2 (module docstring): (Bx, By) of
    B + (l²/4)·∂²B/∂z'² + B_g and (Gxx, Gxy, Gyy), all in the plane's frame."""
    e = np.asarray(plane, float)
    normal = np.cross(e[0], e[1])
    field = np.zeros((5, 3))
    field[:2] = e
    gradient = np.zeros((5, 3, 3))
    gradient[2] = np.outer(e[0], e[0])
    gradient[3] = np.outer(e[0], e[1])
    gradient[4] = np.outer(e[1], e[1])
    hessian = np.zeros((5, 3, 3, 3))
    hessian[:2] = 0.25 * lever_m**2 * np.einsum("pi,j,k->pijk", e, normal, normal)
    return Readout(field, gradient, hessian, np.asarray(gravity_field_t, float))


def gravity_field_t(probe: Probe, gravity_m_per_s2: ArrayLike) -> np.ndarray:
    """B_g = (a·l/m)·g: the field whose energy on the moment equals the weight's on the lever."""
    return probe.magnet_mass_kg * probe.lever_m / probe.moment_am2 * np.asarray(gravity_m_per_s2, float)


def sweep_observation(
    decomposition: Decomposition,
    position_m: ArrayLike,
    plane: ArrayLike,
    probe: Probe,
    group: int,
    gravity_m_per_s2: ArrayLike = (0.0, 0.0, -9.80665),
) -> Observation:
    """A decomposed sweep at ``position_m`` (the magnet's rest position) in the plane of rows
    e1, e2 (θ0 counted from e1, as the sweep's stage turns it). ValueError if the sweep has no
    decomposition or its gradient is not determined (a free f00 leaves Gxx, Gyy open)."""
    if not decomposition.ok:
        raise ValueError(f"a sweep without field and gradient cannot enter a map: {decomposition.report()}")
    values = np.concatenate([decomposition.field_t, decomposition.gradient_t_per_m])
    covariance = np.zeros((5, 5))
    covariance[:2, :2] = decomposition.field_covariance_t2
    covariance[2:, 2:] = decomposition.gradient_covariance
    readout = plane_readout(plane, probe.lever_m, gravity_field_t(probe, gravity_m_per_s2))
    return Observation(
        np.asarray(position_m, float), np.asarray(plane, float), values, covariance, readout, group, SWEEP_COMPONENTS
    )


def hall_observation(position_m: ArrayLike, field_t: ArrayLike, covariance_t2: ArrayLike, group: int) -> Observation:
    """A 3-axis Hall probe's reading B (3,) with its covariance at ``position_m``."""
    readout = Readout(np.eye(3), np.zeros((3, 3, 3)), np.zeros((3, 3, 3, 3)), np.zeros(3))  # nothing added
    return Observation(
        np.asarray(position_m, float),
        None,
        np.asarray(field_t, float),
        np.asarray(covariance_t2, float),
        readout,
        group,
        HALL_COMPONENTS,
    )
