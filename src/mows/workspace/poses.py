"""The arm's pose error as a prior the fit carries (errors in variables).

The arm reports where it put the probe (``measured_cp``), not where the probe is: the true
position is p̂ + δp and the true orientation R(δφ)·R̂, with δp ~ N(0, σ_p²·I) and the small
rotation vector δφ ~ N(0, σ_φ²·I) (the arm's stated accuracy). A map that ignores them reads each
sweep at the wrong place and along the wrong directions: at 1° a 1.5 mT field out of the plane
leaks 26 µT into it. Here every sweep's pose error is fitted with the coefficients, its prior a
term of the objective:

    Σ_s ‖L_s⁻¹·(y_s − D_s(η_s)·c − o_s(η_s))‖² + Σ_s ‖η_s / σ‖²,   η_s = (δp_s, δφ_s).

The model is linear in c and smooth in η, so Gauss–Newton converges in a few steps (∂/∂η by
central differences of the readout at the moved and turned pose). Each sweep measures the
gradient, so where the field changes over the pose error the data see the error themselves;
where they cannot, the prior bounds it. The coefficients' covariance is the c-block of the
inverse of the joint normal matrix: the pose errors' share of the uncertainty is in every σ the
model reports.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from mows.workspace.fit import WorkspaceModel, apply_readout, point_designs, whiten
from mows.workspace.harmonics import SolidHarmonics
from mows.workspace.observations import Observation

ITERATIONS = 4
STEPS = np.r_[np.full(3, 1e-6), np.full(3, 1e-6)]  # m, rad: the model is smooth over mm and degrees


@dataclasses.dataclass(frozen=True)
class PoseError:
    """The arm's stated accuracy: σ of each position component (m) and of each component of
    the small rotation vector (rad)."""

    position_std_m: float
    angle_std_rad: float

    def __post_init__(self) -> None:
        for name in ("position_std_m", "angle_std_rad"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} = {value!r}: a positive standard deviation")

    @property
    def std(self) -> np.ndarray:
        return np.r_[np.full(3, self.position_std_m), np.full(3, self.angle_std_rad)]


def rotation(vector_rad: np.ndarray) -> np.ndarray:
    """The rotation by the rotation vector ``vector_rad`` (Rodrigues)."""
    angle = float(np.linalg.norm(vector_rad))
    if angle == 0.0:
        return np.eye(3)
    k = np.asarray(vector_rad, float) / angle
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * cross + (1.0 - math.cos(angle)) * cross @ cross


def moved(obs: Observation, error: np.ndarray) -> Observation:
    """``obs`` taken at its reported pose moved by ``error`` = (δp, δφ)."""
    turn = rotation(error[3:])
    plane = None if obs.plane is None else obs.plane @ turn.T
    return dataclasses.replace(
        obs, position_m=obs.position_m + error[:3], plane=plane, readout=obs.readout.rotated(turn)
    )


@dataclasses.dataclass(frozen=True)
class PoseFit:
    """The model with the pose errors carried; ``pose_errors`` (S, 6): each observation's
    fitted (δp, δφ), and their σ ``pose_error_std``."""

    model: WorkspaceModel
    pose_errors: np.ndarray
    pose_error_std: np.ndarray


def _linearised(basis: SolidHarmonics, obs: Observation, error: np.ndarray, coefficients: np.ndarray):
    """Whitened design in c, residual and Jacobian in η at ``error``: forward differences, the
    three turns from the designs at one position (a turn changes the readout, not the point)."""
    here = moved(obs, error)
    designs = point_designs(basis, here.position_m)
    design, data = whiten(here, apply_readout(designs, here.readout))
    residual = data - design @ coefficients
    jacobian = np.empty((data.size, 6))
    for k in range(6):
        shifted = moved(obs, error + np.eye(6)[k] * STEPS[k])
        at = point_designs(basis, shifted.position_m) if k < 3 else designs
        shifted_design, shifted_data = whiten(shifted, apply_readout(at, shifted.readout))
        # ∂(model − data)/∂η, the whitened factor being the same at every pose
        jacobian[:, k] = (residual - (shifted_data - shifted_design @ coefficients)) / STEPS[k]
    return design, residual, jacobian


def fit_with_pose_errors(
    observations: Sequence[Observation], basis: SolidHarmonics, pose_error: PoseError, start: WorkspaceModel
) -> PoseFit:
    """Gauss–Newton over the coefficients and every observation's pose error (module
    docstring), from the model ``start`` fitted at the reported poses."""
    n_obs, k = len(observations), basis.size
    coefficients = start.coefficients.copy()
    errors = np.zeros((n_obs, 6))
    prior = 1.0 / pose_error.std
    for _ in range(ITERATIONS):
        normal = np.zeros((k + 6 * n_obs, k + 6 * n_obs))
        gradient = np.zeros(k + 6 * n_obs)
        chi2 = 0.0
        for s, obs in enumerate(observations):
            design, residual, jacobian = _linearised(basis, obs, errors[s], coefficients)
            block = np.hstack([design, jacobian])
            index = np.r_[np.arange(k), k + 6 * s + np.arange(6)]
            normal[np.ix_(index, index)] += block.T @ block
            gradient[index] += block.T @ residual
            chi2 += float(residual @ residual)
        pose_rows = k + np.arange(6 * n_obs)
        normal[pose_rows, pose_rows] += np.tile(prior**2, n_obs)
        gradient[pose_rows] -= (errors * prior**2).ravel()
        step = np.linalg.solve(normal, gradient)
        coefficients = coefficients + step[:k]
        errors = errors + step[k:].reshape(n_obs, 6)
    covariance = np.linalg.inv(normal)
    values = sum(obs.values.size for obs in observations)
    chi2 += float(np.sum((errors * prior) ** 2))
    model = WorkspaceModel(basis, coefficients, covariance[:k, :k], chi2, values - k)
    pose_std = np.sqrt(np.diag(covariance)[k:]).reshape(n_obs, 6)
    return PoseFit(model, errors, pose_std)
