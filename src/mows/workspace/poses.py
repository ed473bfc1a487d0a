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

To first order the same fit is a plain weighted one whose every observation's covariance holds
its pose error's share, C + J·Σ_η·Jᵀ with J = ∂(reading)/∂η (the pose errors marginalised,
:func:`pose_marginalised`). That is how the degree is chosen with the pose error present
(:func:`choose_degree_with_pose_error`): the cross-validation over sweeps then weighs each sweep
as the carried fit does. Without it the choice follows the sweeps' noise alone, 50 nT in B,
while a 0.1 mm error moves B by 3 µT in a gradient of 30 mT/m; it picks a degree the data,
blurred by the pose errors, cannot determine.

What no fit can see is the mean of the sweeps' pose errors: a field shifted by δ̄ and turned by
δφ̄ fits the sweeps as well as the true one, so a map of N sweeps is off by at least
G·δ̄ + δφ̄ × B in B, with δ̄ ~ N(0, σ_p²/N) (:func:`frame_bound`). :func:`error_split` splits a
carried map's σ by cause: that mean's share (the bound), the rest of the pose errors' (each
sweep's own, which the coefficients partly absorb) and the sweeps' noise's.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from mows.workspace.fit import (
    DegreeChoice,
    WorkspaceModel,
    apply_readout,
    choose_degree,
    fit,
    readout_design,
    whiten,
)
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


def pose_jacobian(model: WorkspaceModel, obs: Observation) -> np.ndarray:
    """(k, 6): ∂(what ``obs`` reads by ``model``)/∂η at its reported pose, central differences."""
    steps = np.diag(STEPS)
    # the point itself, then moved by +h and by −h along each axis: a turn changes the readout only
    designs = _designs_at(
        model.basis, obs.position_m + np.concatenate([np.zeros((1, 3)), steps[:3, :3], -steps[:3, :3]])
    )

    def reading(k: int, sign: float) -> np.ndarray:
        readout = moved(obs, sign * steps[k]).readout
        at = designs[k + (1 if sign > 0 else 4)] if k < 3 else designs[0]
        return apply_readout(at, readout) @ model.coefficients + readout.offset

    return np.stack([(reading(k, 1.0) - reading(k, -1.0)) / (2.0 * STEPS[k]) for k in range(6)], axis=1)


def _designs_at(basis: SolidHarmonics, points_m: np.ndarray) -> list[tuple[np.ndarray, ...]]:
    """:func:`mows.workspace.fit.point_designs` at each of ``points_m`` (n, 3), in one call per rank."""
    ranks = [basis.design(points_m, rank) for rank in range(3)]
    return [tuple(rank[i] for rank in ranks) for i in range(len(points_m))]


def pose_marginalised(observations: Sequence[Observation], model: WorkspaceModel, pose_error: PoseError):
    """Each observation with its pose error's share in its covariance, C + J·diag(σ²)·Jᵀ, J by
    ``model`` at the reported pose (module docstring)."""
    variance = np.diag(pose_error.std**2)
    marginalised = []
    for obs in observations:
        jacobian = pose_jacobian(model, obs)
        marginalised.append(dataclasses.replace(obs, covariance=obs.covariance + jacobian @ variance @ jacobian.T))
    return marginalised


def choose_degree_with_pose_error(
    observations: Sequence[Observation], degrees: Sequence[int], pose_error: PoseError, plain: WorkspaceModel
) -> DegreeChoice:
    """The degree cross-validation over sweeps chooses with each sweep's pose error in its
    covariance (module docstring), about ``plain``'s centre and scale. J needs B, G and H at
    each pose to a few per cent: ``plain``, a fit that ignores the pose error, gives them."""
    marginalised = pose_marginalised(observations, plain, pose_error)
    return choose_degree(marginalised, degrees, plain.basis.centre_m, plain.basis.scale_m)


def frame_bound(field_t: np.ndarray, gradient_t_per_m: np.ndarray, pose_error: PoseError, count: int) -> float:
    """The rms error of B over its rms that a map of ``count`` sweeps cannot avoid at points
    where the field is ``field_t`` (N, 3) and G ``gradient_t_per_m`` (N, 3, 3): the sweeps' mean
    pose error, a shift and a turn of the whole map the data cannot see (module docstring),
    σ_p/√count and σ_φ/√count per component."""
    shift_var, turn_var = pose_error.position_std_m**2 / count, pose_error.angle_std_rad**2 / count
    # E|G·δ|² = σ²‖G‖², E|δφ × B|² = 2σ²|B|²
    error_var = shift_var * np.sum(gradient_t_per_m**2, axis=(1, 2)) + 2.0 * turn_var * np.sum(field_t**2, axis=1)
    return math.sqrt(np.mean(error_var) / np.mean(np.sum(field_t**2, axis=1)))


@dataclasses.dataclass(frozen=True)
class ErrorSplit:
    """The rms σ of B (T) and of G (T/m) over a map's points, split by cause (:func:`error_split`):
    each sweep's ``noise``, the ``common`` mean of the sweeps' pose errors that no fit can see,
    and the ``differential`` rest of the pose errors, each sweep's own."""

    field_t: dict[str, float]
    gradient_t_per_m: dict[str, float]


def error_split(
    observations: Sequence[Observation], model: WorkspaceModel, pose_error: PoseError, points_m: np.ndarray
) -> ErrorSplit:
    """The σ of the map the pose error is carried in, to first order, split by cause: with J_s the
    reading's change with sweep s's pose at ``model`` and V_s = C_s + J_s·Σ·J_sᵀ, the estimate
    ĉ = Σ_s M_s·y_s, M_s = (Σ AᵀV⁻¹A)⁻¹·A_sᵀ·V_s⁻¹, has the covariance Σ_s M_s·C_s·M_sᵀ from the
    noise and Σ_s M_s·J_s·Σ·J_sᵀ·M_sᵀ from the pose errors, of which K·Σ·Kᵀ/N (K = Σ_s M_s·J_s)
    comes from their mean, the shift and turn of the whole map (:func:`frame_bound`)."""
    basis = model.basis
    designs, jacobians, inverses = [], [], []
    variance = np.diag(pose_error.std**2)
    for obs in observations:
        designs.append(readout_design(basis, obs.position_m, obs.readout))
        jacobians.append(pose_jacobian(model, obs))
        inverses.append(np.linalg.inv(obs.covariance + jacobians[-1] @ variance @ jacobians[-1].T))
    covariance = np.linalg.inv(sum(a.T @ v @ a for a, v in zip(designs, inverses)))
    estimators = [covariance @ a.T @ v for a, v in zip(designs, inverses)]
    noise = sum(m @ obs.covariance @ m.T for m, obs in zip(estimators, observations))
    pose = sum(m @ j @ variance @ j.T @ m.T for m, j in zip(estimators, jacobians))
    mean = sum(m @ j for m, j in zip(estimators, jacobians))
    common = mean @ variance @ mean.T / len(observations)
    parts = {"noise": noise, "common": common, "differential": pose - common}
    count = len(np.atleast_2d(points_m))
    field, gradient = (basis.design(points_m, rank).reshape(-1, basis.size) for rank in (0, 1))

    def rms(design: np.ndarray, part: np.ndarray) -> float:  # of the vector's (tensor's) length
        return math.sqrt(max(float(np.einsum("ik,kl,il->", design, part, design)), 0.0) / count)

    return ErrorSplit({k: rms(field, v) for k, v in parts.items()}, {k: rms(gradient, v) for k, v in parts.items()})


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
    designs = _designs_at(basis, here.position_m + np.vstack([np.zeros(3), np.diag(STEPS[:3])]))
    design, data = whiten(here, apply_readout(designs[0], here.readout))
    residual = data - design @ coefficients
    jacobian = np.empty((data.size, 6))
    for k in range(6):
        shifted = moved(obs, error + np.eye(6)[k] * STEPS[k])
        at = designs[k + 1] if k < 3 else designs[0]
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


@dataclasses.dataclass(frozen=True)
class CarriedMap:
    """A map with the pose errors carried: the ``plain`` fit that ignores them, at the degree
    chosen without them; the degree's ``choice`` with them; the ``carried`` fit at it."""

    plain: WorkspaceModel
    choice: DegreeChoice
    carried: PoseFit


def map_with_pose_error(
    observations: Sequence[Observation],
    degrees: Sequence[int],
    pose_error: PoseError,
    centre_m: Sequence[float],
    scale_m: float,
) -> CarriedMap:
    """The degree chosen with the pose error (:func:`choose_degree_with_pose_error`) and the
    coefficients fitted with every sweep's pose error (:func:`fit_with_pose_errors`)."""
    centre = tuple(float(c) for c in centre_m)
    plain_choice = choose_degree(observations, degrees, centre, scale_m)
    plain = fit(observations, SolidHarmonics(plain_choice.chosen, centre, scale_m))
    choice = choose_degree_with_pose_error(observations, degrees, pose_error, plain)
    basis = SolidHarmonics(choice.chosen, centre, scale_m)
    return CarriedMap(plain, choice, fit_with_pose_errors(observations, basis, pose_error, fit(observations, basis)))
