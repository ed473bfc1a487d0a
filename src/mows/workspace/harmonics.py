"""The scalar potential of a source-free region as regular solid harmonics, and its derivatives.

In a region without currents or magnetised matter B = −∇Φ with ∇²Φ = 0. Inside a ball that
holds no source, Φ is a sum of regular solid harmonics r^n·Y_nm(θ, φ): for each degree n the
homogeneous polynomials of degree n in (x, y, z) that the Laplacian sends to zero, a space of
dimension 2n + 1. Up to degree L the potential has (L + 1)² − 1 coefficients (degree 0, a
constant, has no field). Every field of this form has ∇·B = −∇²Φ = 0 and ∇×B = −∇×∇Φ = 0
exactly, so its gradient G_ij = ∂B_i/∂x_j = −∂_i∂_jΦ is symmetric and traceless and its
Hessian H_ijk = −∂_i∂_j∂_kΦ is symmetric and traceless in any pair, whatever the coefficients.

Each degree's basis is computed once as the null space of the Laplacian over that degree's
monomials (an orthonormal basis of the same space the r^n·Y_nm span); derivatives of monomials
are exact. Coordinates are u = (x − centre)/scale, so that the workspace is |u| ≲ 1 and the
design stays well conditioned; Φ = scale·Σ c_k·P_k(u) with the coefficients c_k in tesla, so
B = −Σ c_k·∇_u P_k, G = −Σ c_k·∇_u∇_u P_k / scale and H = −Σ c_k·∇_u∇_u∇_u P_k / scale².
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math

import numpy as np
from numpy.typing import ArrayLike


@functools.cache
def _monomials(degree: int) -> np.ndarray:
    """Exponents (a, b, c), a + b + c = degree, of the monomials x^a·y^b·z^c, shape (M, 3)."""
    return np.array([(a, b, degree - a - b) for a in range(degree, -1, -1) for b in range(degree - a, -1, -1)], int)


@functools.cache
def harmonic_basis(degree: int) -> np.ndarray:
    """(M, 2·degree + 1): monomial coefficients of an orthonormal basis of the harmonic
    homogeneous polynomials of ``degree`` (the null space of the Laplacian on them)."""
    exponents = _monomials(degree)
    if degree < 2:
        return np.eye(len(exponents))
    lower = {tuple(e): i for i, e in enumerate(_monomials(degree - 2))}
    laplacian = np.zeros((len(lower), len(exponents)))
    for column, exponent in enumerate(exponents):
        for axis in range(3):
            power = exponent[axis]
            if power >= 2:
                reduced = exponent.copy()
                reduced[axis] -= 2
                laplacian[lower[tuple(reduced)], column] += power * (power - 1)
    _, singular, vt = np.linalg.svd(laplacian)
    rank = int(np.sum(singular > 1e-10 * singular[0]))
    basis = vt[rank:].T
    if basis.shape[1] != 2 * degree + 1:
        raise AssertionError(f"harmonic polynomials of degree {degree}: {basis.shape[1]} found, {2 * degree + 1} exist")
    return basis


def coefficient_count(max_degree: int) -> int:
    """(L + 1)² − 1: the coefficients of degrees 1 … L."""
    return (max_degree + 1) ** 2 - 1


@functools.cache
def _derivative_terms(degree: int, order: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What ∂^order leaves of each monomial of ``degree``: the indices of those it does not
    send to zero, their reduced exponents and their factors. Cached: a map's fit asks for the
    same few (degree, order) pairs tens of thousands of times, at a handful of points each."""
    exponents = _monomials(degree)
    reduced = exponents - np.array(order)
    factor = np.ones(len(exponents))
    for axis in range(3):
        for step in range(order[axis]):
            factor = factor * (exponents[:, axis] - step)
    alive = np.flatnonzero(np.all(reduced >= 0, axis=1) & (factor != 0))
    return alive, reduced[alive], factor[alive]


def _monomial_derivative(degree: int, order: tuple[int, int, int], u: np.ndarray) -> np.ndarray:
    """∂^order of each monomial of ``degree`` at the points u (N, 3): shape (N, M)."""
    alive, reduced, factor = _derivative_terms(degree, order)
    values = np.zeros((u.shape[0], len(_monomials(degree))))
    if len(alive):
        powers = np.ones((u.shape[0], len(alive)))
        for axis in range(3):
            powers = powers * u[:, axis : axis + 1] ** reduced[:, axis]
        values[:, alive] = powers * factor
    return values


@dataclasses.dataclass(frozen=True)
class SolidHarmonics:
    """Regular solid harmonics of degrees 1 … ``max_degree`` about ``centre_m``, coordinates
    scaled by ``scale_m`` (module docstring). The design matrices map the coefficients (K,),
    tesla, to B, G or H at each point."""

    max_degree: int
    centre_m: tuple = (0.0, 0.0, 0.0)
    scale_m: float = 0.05

    def __post_init__(self) -> None:
        if int(self.max_degree) != self.max_degree or self.max_degree < 1:
            raise ValueError(f"max_degree = {self.max_degree!r}: an integer ≥ 1")
        if not (math.isfinite(self.scale_m) and self.scale_m > 0):
            raise ValueError(f"scale_m = {self.scale_m!r}: a positive length")

    @property
    def size(self) -> int:
        return coefficient_count(self.max_degree)

    def _potential_derivative(self, points_m: ArrayLike, order: tuple[int, int, int]) -> np.ndarray:
        """∂^order Φ_k / scale^(|order| − 1) for each basis potential, shape (N, K)."""
        points = np.atleast_2d(np.asarray(points_m, float))
        u = (points - np.asarray(self.centre_m, float)) / self.scale_m
        blocks = [_monomial_derivative(n, order, u) @ harmonic_basis(n) for n in range(1, self.max_degree + 1)]
        return np.concatenate(blocks, axis=1) / self.scale_m ** (sum(order) - 1)

    def design(self, points_m: ArrayLike, rank: int) -> np.ndarray:
        """−∂^(rank+1)Φ per coefficient: B (rank 0, shape (N, 3, K)), G (rank 1, (N, 3, 3, K))
        or H (rank 2, (N, 3, 3, 3, K)) at each point for unit coefficients."""
        points = np.atleast_2d(np.asarray(points_m, float))
        shape = (points.shape[0],) + (3,) * (rank + 1) + (self.size,)
        design = np.zeros(shape)
        for axes in itertools.combinations_with_replacement(range(3), rank + 1):
            order = tuple(int(axes.count(axis)) for axis in range(3))
            value = -self._potential_derivative(points, order)  # type: ignore[arg-type]
            for permuted in set(itertools.permutations(axes)):
                design[(slice(None),) + permuted] = value
        return design
