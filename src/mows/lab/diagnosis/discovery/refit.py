"""The kept terms refitted jointly: strengths, σ, significance and cross-validated gain.

The kept terms are refitted jointly by weighted least squares on the projected columns (the
model's parameters free, Frisch–Waugh) for their strengths, each the channel's parameter per unit
of the monomial, with σ inflated by the scatter they leave (φ = max(1, χ²/dof)). A term is
reported only when (a) its likelihood-ratio p-value, Δχ²/φ ~ χ²(1), is below :data:`ALPHA`
divided by the library size (Bonferroni) and (b) its cross-validated gain is positive: the
held-out χ² over the grouped folds (:func:`mows.lab.data.folds.cv_folds`), each fold predicted by
the linearised refit of the model's parameters and the other terms on the rest, without the term
minus with it. The weakest failing term is dropped and the rest refitted, until every term passes.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.stats

from mows.lab.diagnosis.discovery.selection import Searched
from mows.lab.diagnosis.projections import unit_columns

ALPHA = 0.01  # family-wise level (Bonferroni over the library) of a reported term


@dataclasses.dataclass
class Refit:
    """The joint least-squares refit of some terms (indices into the searched library)."""

    chosen: list[int]
    coefficients: np.ndarray  # per unit column
    covariance: np.ndarray  # per unit column, inflated by φ
    gain_chi2: np.ndarray  # Δχ² of each (drop-one)
    p_values: np.ndarray  # of Δχ²/φ ~ χ²(1)
    cv_gain_chi2: np.ndarray  # held-out χ² without minus with each


@dataclasses.dataclass
class Residual:
    """The weighted residual r of a fit with the model's (column-normalised) Jacobian, its rank
    and the grouped cross-validation folds: what every refit of terms works against."""

    values: np.ndarray
    jacobian: np.ndarray
    model_rank: int
    folds: list[np.ndarray]

    def scatter(self, columns: np.ndarray) -> float:
        """φ = max(1, χ²/dof) of the residual after least squares on ``columns`` beside the model."""
        left = self.values - columns @ np.linalg.lstsq(columns, self.values, rcond=None)[0]
        return max(1.0, float(left @ left) / max(len(left) - self.model_rank - columns.shape[1], 1))

    def chi2(self, columns: np.ndarray) -> float:
        """χ² of the residual after least squares on ``columns`` (projected off the model)."""
        left = self.values - columns @ np.linalg.lstsq(columns, self.values, rcond=None)[0]
        return float(left @ left)


def refit(searched: Searched, chosen: list[int], residual: Residual) -> Refit:
    """Strengths, σ, Δχ², p-values and cross-validated gains of the ``chosen`` terms together."""
    columns = searched.unit[:, chosen]
    coefficients = np.linalg.lstsq(columns, residual.values, rcond=None)[0]
    phi = residual.scatter(columns)
    inverse = np.linalg.pinv(columns.T @ columns)
    gain = coefficients**2 / np.diag(inverse)
    design = unit_columns(np.column_stack([residual.jacobian, searched.weighted[:, chosen]]))
    width = residual.jacobian.shape[1]
    held_out = _held_out_chi2(design, residual)
    cv_gain = [_held_out_chi2(np.delete(design, width + i, axis=1), residual) - held_out for i in range(len(chosen))]
    return Refit(chosen, coefficients, inverse * phi, gain, scipy.stats.chi2.sf(gain / phi, 1), np.array(cv_gain))


def _held_out_chi2(design: np.ndarray, residual: Residual) -> float:
    """Σ over the folds of the χ² of the fold's rows predicted by least squares of the residual on
    ``design`` over the other rows (the linearised refit without the fold)."""
    total = 0.0
    for rows in residual.folds:
        train = np.ones(len(residual.values), bool)
        train[rows] = False
        coefficients = np.linalg.lstsq(design[train], residual.values[train], rcond=None)[0]
        left = residual.values[rows] - design[rows] @ coefficients
        total += float(left @ left)
    return total


def significant(searched: Searched, chosen: list[int], residual: Residual) -> Refit:
    """The refit of the ``chosen`` terms that all pass (module docstring: Bonferroni over the
    library, positive cross-validated gain), dropping the weakest failing one at a time."""
    library_size = searched.unit.shape[1]
    while chosen:
        found = refit(searched, chosen, residual)
        failing = (found.p_values * library_size > ALPHA) | (found.cv_gain_chi2 <= 0)
        if not failing.any():
            return found
        weakest = np.flatnonzero(failing)[np.argmin(found.gain_chi2[failing])]
        chosen = [j for i, j in enumerate(chosen) if i != weakest]
    empty = np.zeros(0)
    return Refit([], empty, np.zeros((0, 0)), empty, empty, empty)
