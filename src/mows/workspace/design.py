"""The next best pose: where one more sweep shrinks the map's uncertainty the most.

The map's information about its coefficients is M = Σ AᵀC⁻¹A over the observations so far
(plus a weak prior that keeps it invertible before the map is determined). A sweep at a
candidate pose adds its readout's rows A with the covariance C a sweep there is expected to
have. Two criteria are offered, both exact rank-5 updates:

``D``  the gain in log det M: log det(I + C^(-1/2)·A·M⁻¹·Aᵀ·C^(-1/2)), the volume of the
       coefficients' uncertainty ellipsoid shrunk (D-optimal design);
``I``  the fall of the mean predicted variance of B over the workspace points of interest
       Z: mean over them of trace(Z·ΔΣ·Zᵀ), ΔΣ = Σ·Aᵀ(C + A·Σ·Aᵀ)⁻¹·A·Σ (I-optimal).

The candidates are poses the arm can reach (:mod:`mows.workspace.arm` says which); the choice
is greedy, one sweep at a time, as the mapper asks the arm for one pose after another.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from mows.workspace.fit import readout_design
from mows.workspace.harmonics import SolidHarmonics
from mows.workspace.observations import Observation, Readout

CRITERIA = ("D", "I")
# σ of each coefficient (T) before any sweep: far wider than any field a probe measures.
PRIOR_STD_T = 1.0


def information(basis: SolidHarmonics, observations: Sequence[Observation]) -> np.ndarray:
    """M = Σ AᵀC⁻¹A + I/PRIOR_STD_T² over ``observations``."""
    total = np.eye(basis.size) / PRIOR_STD_T**2
    for obs in observations:
        design = readout_design(basis, obs.position_m, obs.readout)
        total += design.T @ np.linalg.solve(obs.covariance, design)
    return total


def candidate_designs(basis: SolidHarmonics, candidates: Sequence[tuple[np.ndarray, Readout]]) -> list[np.ndarray]:
    """Each candidate's rows A (k, K) at its (position, readout)."""
    return [readout_design(basis, position, readout) for position, readout in candidates]


def gains(
    basis: SolidHarmonics,
    info: np.ndarray,
    designs: Sequence[np.ndarray],
    covariance: np.ndarray,
    criterion: str = "D",
    points_m: np.ndarray | None = None,
) -> np.ndarray:
    """Each candidate's gain (module docstring) for a sweep of ``covariance`` with rows
    ``designs`` (:func:`candidate_designs`)."""
    if criterion not in CRITERIA:
        raise ValueError(f"criterion {criterion!r}: one of {CRITERIA}")
    sigma = np.linalg.inv(info)
    root = np.linalg.cholesky(np.linalg.inv(covariance))
    field_design = None
    if criterion == "I":
        if points_m is None:
            raise ValueError("the I-optimal criterion needs the workspace points of interest")
        field_design = basis.design(points_m, 0).reshape(-1, basis.size) / math.sqrt(len(points_m))
    result = np.empty(len(designs))
    for index, design in enumerate(designs):
        if field_design is None:
            whitened = root.T @ design
            result[index] = np.linalg.slogdet(np.eye(design.shape[0]) + whitened @ sigma @ whitened.T)[1]
        else:
            projected = design @ sigma
            update = projected.T @ np.linalg.solve(covariance + projected @ design.T, projected)
            result[index] = np.einsum("ij,jk,ik->", field_design, update, field_design)
    return result


def next_best(
    basis: SolidHarmonics,
    info: np.ndarray,
    designs: Sequence[np.ndarray],
    covariance: np.ndarray,
    criterion: str = "D",
    points_m: np.ndarray | None = None,
) -> int:
    """The index of the candidate of largest gain given the information ``info`` so far
    (:func:`information`); ValueError when there is none (nothing within the arm's reach)."""
    if not designs:
        raise ValueError("no candidate pose within the arm's reach")
    return int(np.argmax(gains(basis, info, designs, covariance, criterion, points_m)))


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation matrix uniform over SO(3) (QR of a Gaussian matrix, signs fixed)."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    return q if np.linalg.det(q) > 0 else -q


def boundary_positions(count: int, radius_m: float, centre_m: ArrayLike = (0, 0, 0)) -> np.ndarray:
    """``count`` positions on the workspace's bounding sphere, each as far from those before it
    as the sphere allows (farthest-point order over a Fibonacci lattice), so that every prefix
    is spread evenly. A harmonic field inside a ball is fixed by its values on the boundary,
    where the higher degrees are also largest: the boundary is where to measure."""
    candidates = 20 * count
    index = np.arange(candidates) + 0.5
    z = 1.0 - 2.0 * index / candidates
    azimuth = math.pi * (1.0 + math.sqrt(5.0)) * index
    lattice = np.stack([np.sqrt(1 - z * z) * np.cos(azimuth), np.sqrt(1 - z * z) * np.sin(azimuth), z], axis=1)
    chosen = [0]
    distance = np.linalg.norm(lattice - lattice[0], axis=1)
    while len(chosen) < count:
        chosen.append(int(np.argmax(distance)))
        distance = np.minimum(distance, np.linalg.norm(lattice - lattice[chosen[-1]], axis=1))
    return np.asarray(centre_m, float) + radius_m * lattice[chosen]
