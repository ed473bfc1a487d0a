"""The linear algebra of every test: directions projected orthogonally to what the fit absorbs.

Everything is measured against what the current fit can already absorb. With J the Jacobian
of the weighted residuals r = (f − model)/σ over the current model's free parameters, every
test direction (a harmonic of θ0, a covariate, a candidate effect's parameters at 0) is first
projected orthogonally to J: P⊥ = I − Q·Qᵀ, Q an orthonormal basis of J. A
:class:`Signature` holds such a projected direction set and its score statistic against the
residual, S = ‖Uᵀr‖² (U an orthonormal basis of the projected columns), ~ χ²(rank) under
the model.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.stats

RANK_RTOL = 1e-3  # a projected direction shorter than this (relative) is absorbed by the model
SPAN_COSINE = 0.999  # cosine of the largest principal angle between two spans that are the same


def orthonormal_basis(columns: np.ndarray, reference_norm: float | None = None) -> np.ndarray:
    """Orthonormal basis (n, r) of the column space, dropping directions below RANK_RTOL of
    ``reference_norm`` (default: the largest singular value)."""
    columns = np.asarray(columns, float).reshape(len(columns), -1)
    if columns.shape[1] == 0:
        return columns
    u, s, _ = np.linalg.svd(columns, full_matrices=False)
    scale = s[0] if reference_norm is None else reference_norm
    return u[:, s > RANK_RTOL * scale] if scale > 0 else u[:, :0]


def unit_columns(columns: np.ndarray) -> np.ndarray:
    """``columns`` each at unit length (zero columns stay zero): parameters of very different
    scales (f00 in Hz, a temperature coefficient in 1/K) keep their directions in a basis."""
    norms = np.linalg.norm(columns, axis=0)
    return np.divide(columns, norms, out=np.zeros_like(columns), where=norms > 0)


def project_out(columns: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """Columns with their components along the orthonormal ``basis`` removed."""
    return columns - basis @ (basis.T @ columns)


@dataclasses.dataclass
class Signature:
    """A test direction set after projection: basis U (n, r), coefficients of the residual."""

    basis: np.ndarray
    projected: np.ndarray
    statistic: float
    rank: int

    @property
    def p_value(self) -> float:
        return float(scipy.stats.chi2.sf(self.statistic, self.rank)) if self.rank else 1.0

    @property
    def fitted_signal(self) -> np.ndarray:
        return self.basis @ self.coefficients_in_basis

    coefficients_in_basis: np.ndarray
    columns: np.ndarray | None = None  # before projection (None for a signature on another table)


def signature(columns: np.ndarray, model_basis: np.ndarray, residual: np.ndarray) -> Signature:
    """Project ``columns`` orthogonally to the model and score them against ``residual``."""
    columns = np.asarray(columns, float).reshape(len(residual), -1)
    projected = project_out(columns, model_basis)
    norm = np.linalg.norm(columns, axis=0).max() if columns.size else 0.0
    basis = orthonormal_basis(projected, norm)
    coefficients = basis.T @ residual
    return Signature(basis, projected, float(coefficients @ coefficients), basis.shape[1], coefficients, columns)


def cosine_within(vector: np.ndarray, basis: np.ndarray) -> float:
    norm = np.linalg.norm(vector)
    return float(np.linalg.norm(basis.T @ vector) / norm) if norm > 0 and basis.shape[1] else 0.0


def same_span(a: np.ndarray, b: np.ndarray) -> bool:
    """True when the orthonormal bases ``a`` and ``b`` span the same space (all principal
    angles below 2.6°): directions no data on these rows can tell apart, exact aliases."""
    if a.shape[1] == 0 or a.shape[1] != b.shape[1]:
        return False
    return float(np.linalg.svd(a.T @ b, compute_uv=False).min()) >= SPAN_COSINE
