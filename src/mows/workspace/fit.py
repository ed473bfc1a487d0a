"""The workspace model: solid-harmonic coefficients by weighted least squares, its predictions
with σ, and the degree chosen by cross-validation over sweeps.

Every observation (:mod:`mows.workspace.observations`) is linear in the coefficients c:
values − offset = (A_B·D_B + A_G·D_G + A_H·D_H)·c, with D the designs of
:class:`mows.workspace.harmonics.SolidHarmonics` at its position. Whitened by the Cholesky
factor of its covariance, all observations stack into one linear least-squares problem; the
coefficients' covariance is (AᵀC⁻¹A)⁻¹. What the data leave undetermined (a direction of c no
observation sees) is reported: the fit refuses a design of lower rank than its coefficients
rather than inventing them. Where χ²/dof exceeds 1 the covariance is scaled by it, as the
sweep's decomposition does: over three simulated navigation systems it brought the pulls of 30
sweeps' maps from 0.93–1.38 to 0.93–1.10 (docs/performance.md).

The degree is chosen by K-fold cross-validation over groups (a sweep's five values are held
out together, as they share a pose): for each candidate degree, each fold is predicted from a
fit to the others, and the score is the held-out −2·log of the predictive density per value,
χ² + log det S with S the measurement's covariance plus the prediction's (less the constant
log 2π). Too low a degree leaves the field's higher terms in the residual (χ² grows); too high a
degree predicts with a wide S (log det S grows); the lowest score wins. χ² alone is no score: it
rewards the unsure prediction, and with the sweeps' pose errors in their covariance it chose a
degree whose folds just determined their coefficients.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from mows.workspace.harmonics import SolidHarmonics, coefficient_count
from mows.workspace.observations import Observation, Readout

DEFAULT_FOLDS = 5


def point_designs(basis: SolidHarmonics, position_m: ArrayLike, ranks: int = 3) -> tuple[np.ndarray, ...]:
    """The designs of B, G and H (the first ``ranks`` of them) at one position: (3, K),
    (3, 3, K), (3, 3, 3, K)."""
    return tuple(basis.design(position_m, rank)[0] for rank in range(ranks))


def apply_readout(designs: tuple[np.ndarray, ...], readout: Readout) -> np.ndarray:
    """(k, K): the readout's values (less the offset) per unit coefficient, from the designs
    at its position (:func:`point_designs`)."""
    rows = np.einsum("pi,ik->pk", readout.field, designs[0])
    if np.any(readout.gradient):
        rows = rows + np.einsum("pij,ijk->pk", readout.gradient, designs[1])
    if np.any(readout.hessian):
        rows = rows + np.einsum("pijl,ijlk->pk", readout.hessian, designs[2])
    return rows


def readout_design(basis: SolidHarmonics, position_m: ArrayLike, readout: Readout) -> np.ndarray:
    """(k, K): the readout's values (less the offset) per unit coefficient at ``position_m``."""
    ranks = 3 if np.any(readout.hessian) else 2 if np.any(readout.gradient) else 1
    return apply_readout(point_designs(basis, position_m, ranks), readout)


def whiten(obs: Observation, design: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``design`` and the observation's data, multiplied by L⁻¹ (C = L·Lᵀ)."""
    factor = np.linalg.cholesky(obs.covariance)
    return np.linalg.solve(factor, design), np.linalg.solve(factor, obs.values - obs.readout.offset)


def whitened_rows(basis: SolidHarmonics, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
    """One observation's design and data, multiplied by L⁻¹ (C = L·Lᵀ)."""
    return whiten(obs, readout_design(basis, obs.position_m, obs.readout))


@dataclasses.dataclass(frozen=True)
class WorkspaceModel:
    """A fitted potential: ``coefficients`` (K,), tesla, and their ``covariance``; ``chi2``
    over ``dof`` of the fit."""

    basis: SolidHarmonics
    coefficients: np.ndarray
    covariance: np.ndarray
    chi2: float
    dof: int

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    def predict(self, design: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Value and σ of each row of ``design`` (..., K)."""
        value = design @ self.coefficients
        variance = np.einsum("...k,kl,...l->...", design, self.covariance, design)
        return value, np.sqrt(np.maximum(variance, 0.0))

    def field_t(self, points_m: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """B (N, 3), tesla, and its σ per component."""
        return self.predict(self.basis.design(points_m, 0))

    def gradient_t_per_m(self, points_m: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """G[i, j] = ∂B_i/∂x_j (N, 3, 3), T/m, and its σ per component."""
        return self.predict(self.basis.design(points_m, 1))

    def observation(self, obs: Observation) -> tuple[np.ndarray, np.ndarray]:
        """What ``obs`` would read by this model, and the model's covariance of it."""
        design = readout_design(self.basis, obs.position_m, obs.readout)
        return design @ self.coefficients + obs.readout.offset, design @ self.covariance @ design.T


def fit(observations: Sequence[Observation], basis: SolidHarmonics) -> WorkspaceModel:
    """Weighted least squares of ``basis``'s coefficients to ``observations``. ValueError when
    they cannot determine every coefficient (too few, or all in a plane the basis cannot see
    out of)."""
    model = _solve(basis, [whitened_rows(basis, obs) for obs in observations])
    # A model that does not fit its data does not get to claim their precision (as the sweep's
    # decomposition, and lmfit): what the degree leaves out shows as χ²/dof > 1.
    return dataclasses.replace(model, covariance=model.covariance * max(1.0, model.chi2_dof))


def _solve(basis: SolidHarmonics, rows: Sequence[tuple[np.ndarray, np.ndarray]]) -> WorkspaceModel:
    design = np.concatenate([r[0] for r in rows])
    data = np.concatenate([r[1] for r in rows])
    if design.shape[0] < basis.size:
        raise ValueError(f"{design.shape[0]} measured values cannot determine {basis.size} coefficients")
    u, singular, vt = np.linalg.svd(design, full_matrices=False)
    if singular[-1] <= 1e-10 * singular[0]:
        raise ValueError(
            f"the observations leave {int(np.sum(singular <= 1e-10 * singular[0]))} of {basis.size} "
            f"coefficients of degree {basis.max_degree} undetermined: measure at more poses, or a lower degree"
        )
    coefficients = vt.T @ ((u.T @ data) / singular)
    covariance = (vt.T / singular**2) @ vt
    residual = data - design @ coefficients
    return WorkspaceModel(basis, coefficients, covariance, float(residual @ residual), design.shape[0] - basis.size)


@dataclasses.dataclass(frozen=True)
class DegreeChoice:
    """The cross-validation: ``scores`` (held-out −2·log predictive density per value) of each of ``degrees``; NaN
    where a fold could not be fitted."""

    degrees: tuple[int, ...]
    scores: tuple[float, ...]
    chosen: int

    def report(self) -> str:
        scores = ", ".join(f"{d}: {s:.3g}" for d, s in zip(self.degrees, self.scores))
        return (
            f"degree {self.chosen} by {len(self.degrees)}-degree cross-validation "
            f"(held-out −2·log density per value {scores})"
        )


def _folds(groups: np.ndarray, n_folds: int) -> list[np.ndarray]:
    unique = np.unique(groups)
    return [np.isin(groups, part) for part in np.array_split(unique, min(n_folds, unique.size))]


def held_out_score(observations: Sequence[Observation], basis: SolidHarmonics, n_folds: int = DEFAULT_FOLDS) -> float:
    """Held-out −2·log predictive density per value over ``n_folds`` folds of whole groups, in
    the whitened units where the measurement's covariance is the identity (module docstring)."""
    groups = np.array([obs.group for obs in observations])
    rows = [whitened_rows(basis, obs) for obs in observations]
    score, count = 0.0, 0
    for held in _folds(groups, n_folds):
        model = _solve(basis, [r for r, h in zip(rows, held) if not h])
        for (design, data), _ in filter(lambda pair: pair[1], zip(rows, held)):
            # in whitened units the measurement's covariance is the identity
            difference = data - design @ model.coefficients
            covariance = np.eye(data.size) + design @ model.covariance @ design.T
            score += float(difference @ np.linalg.solve(covariance, difference)) + np.linalg.slogdet(covariance)[1]
            count += difference.size
    return score / count


def choose_degree(
    observations: Sequence[Observation],
    degrees: Sequence[int],
    centre_m: ArrayLike = (0.0, 0.0, 0.0),
    scale_m: float = 0.05,
    n_folds: int = DEFAULT_FOLDS,
) -> DegreeChoice:
    """The degree of lowest held-out score among ``degrees`` whose folds can all be fitted."""
    values = sum(obs.values.size for obs in observations)
    scores = []
    for degree in degrees:
        basis = SolidHarmonics(degree, tuple(np.asarray(centre_m, float)), scale_m)
        if coefficient_count(degree) >= values:
            scores.append(math.nan)
            continue
        try:
            scores.append(held_out_score(observations, basis, n_folds))
        except ValueError:  # a fold without enough poses for this degree
            scores.append(math.nan)
    finite = [(s, d) for s, d in zip(scores, degrees) if math.isfinite(s)]
    if not finite:
        raise ValueError(f"no degree of {tuple(degrees)} can be cross-validated on {len(observations)} observations")
    return DegreeChoice(tuple(degrees), tuple(scores), min(finite)[1])
