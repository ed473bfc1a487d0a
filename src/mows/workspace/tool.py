"""Force and torque on a magnetic tool (a catheter's or capsule's magnet) anywhere in the map.

A tool of dipole moment m (A·m², fixed in direction by the operator's command) feels the torque
τ = m × B and the force F_i = Σ_j m_j·∂B_j/∂x_i = (G·m)_i (G symmetric where no current flows).
Both are linear in the potential's coefficients, so their σ follow from the coefficients'
covariance exactly, with the correlations between components.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from numpy.typing import ArrayLike

from mows.workspace.fit import WorkspaceModel


@dataclasses.dataclass(frozen=True)
class ToolWrench:
    """Force (N, 3), N, and torque (N, 3), N·m, with σ per component, at each point."""

    force_n: np.ndarray
    force_std_n: np.ndarray
    torque_nm: np.ndarray
    torque_std_nm: np.ndarray


def cross_matrix(vector: ArrayLike) -> np.ndarray:
    """[v]× with [v]×·w = v × w."""
    x, y, z = np.asarray(vector, float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def wrench(model: WorkspaceModel, points_m: ArrayLike, moment_am2: ArrayLike) -> ToolWrench:
    """The force and torque on a dipole ``moment_am2`` (3,) at ``points_m`` (N, 3) by ``model``."""
    moment = np.asarray(moment_am2, float)
    if moment.shape != (3,) or not np.all(np.isfinite(moment)):
        raise ValueError(f"a tool's moment is a finite 3-vector in A·m², got {moment_am2!r}")
    force_design = np.einsum("nijk,j->nik", model.basis.design(points_m, 1), moment)
    torque_design = np.einsum("ij,njk->nik", cross_matrix(moment), model.basis.design(points_m, 0))
    force, force_std = model.predict(force_design)
    torque, torque_std = model.predict(torque_design)
    return ToolWrench(force, force_std, torque, torque_std)
