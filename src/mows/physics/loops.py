"""Current loops: the exact field of a circular filament and the coils built from loops
(:func:`helmholtz_pair`, :func:`anti_helmholtz_pair`, :func:`solenoid`, all :class:`SumSource`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import ellipe, ellipkm1, hyp2f1

from mows.physics.schema import as_points_m, positive, unit_vector3, vector3
from mows.physics.sources import MU0, FieldSource, SumSource

# The loop is a filament: its field diverges on the wire. Closer than this fraction of the
# radius we refuse rather than return a number dominated by the singularity.
WIRE_CLEARANCE = 1e-9

# Loop derivatives: 6th-order central differences of the exact field, step proportional to
# the distance s to the wire (the field is analytic within s, so s is its length scale).
# Against Biot–Savart quadrature of the differentiated kernel (0.002 < s/R < 4) the errors
# are < 3e-11·|B|/s (gradient) and < 4e-9·|B|/s² (Hessian); tests/physics/test_field.py.
_FD_OFFSETS = np.array([-3.0, -2.0, -1.0, 1.0, 2.0, 3.0])
_FD_WEIGHTS = np.array([-1.0, 9.0, -45.0, 45.0, -9.0, 1.0]) / 60.0
GRADIENT_STEP = 5e-3  # × s
HESSIAN_STEP = 1e-2  # × s


def _central_jacobian(func: Callable[[np.ndarray], np.ndarray], points: np.ndarray, step_m: np.ndarray) -> np.ndarray:
    """∂func/∂x_j by a 6th-order central difference with per-point step ``step_m`` (...).

    ``func`` maps (..., 3) → (..., *out); the result has shape (..., *out, 3).
    """
    lead = points.ndim - 1
    shifts = _FD_OFFSETS[:, None, None] * np.eye(3)  # (s, j, 3)
    stencil = points[..., None, None, :] + step_m[..., None, None, None] * shifts
    values = func(stencil)  # (..., s, j, *out)
    values = np.moveaxis(values, (lead, lead + 1), (-2, -1))  # (..., *out, s, j)
    derivative = np.einsum("...sj,s->...j", values, _FD_WEIGHTS)
    return derivative / step_m.reshape(step_m.shape + (1,) * (derivative.ndim - step_m.ndim))


class CurrentLoop(FieldSource):
    """Circular filament of radius ``radius_m`` about ``center_m``, normal ``axis``.

    ``turns`` × ``current_a`` ampere-turns; positive current circulates right-handedly
    about ``axis``, so the field at the centre is +μ0·N·I/(2R)·axis.

    Field: exact, with the complete elliptic integrals K(m), E(m) of parameter
    m = k² = 4Rρ/β² (Smythe; Simpson et al. 2001), α² = (R − ρ)² + z², β² = (R + ρ)² + z²::

        B_z = μ0NI / (2π α² β) · [(R² − ρ² − z²)·E + α²·K]
        B_ρ/ρ = 4μ0NI R² z / (π β⁵) · J(m),   J(m) = ∫₀^{π/2} sin⁴u (1 − m sin²u)^(−3/2) du

    J = (3π/16)·₂F₁(3/2, 5/2; 3; m) = ((2 − m)E − 2(1 − m)K) / (m²(1 − m)); the series
    form is used for m < ½ (the closed form cancels there), the closed form with
    K = ellipkm1(α²/β²) for m ≥ ½ (accurate up to the wire). B = (B_ρ/ρ)·ρ_vec + B_z·axis
    needs no division by ρ, so the axis is an ordinary point.

    Gradient and Hessian: 6th-order central differences of this field, with steps
    :data:`GRADIENT_STEP` and :data:`HESSIAN_STEP` times the distance s to the wire
    (accuracy in the comment above ``GRADIENT_STEP``). Points within :data:`WIRE_CLEARANCE`·R of the wire
    raise ValueError.
    """

    type_name = "loop"
    _linear = ("current_a",)

    def __init__(self, center_m: ArrayLike, axis: ArrayLike, radius_m: float, turns: float, current_a: float) -> None:
        self.center_m = vector3("center_m", center_m)
        self.axis = unit_vector3("axis", axis)
        self.radius_m = positive("radius_m", radius_m)
        self.turns = positive("turns", turns)
        self.current_a = float(current_a)
        if not np.isfinite(self.current_a):
            raise ValueError(f"current_a must be finite, got {current_a!r}")

    def _cylindrical(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(ρ_vec, ρ, z, α²) of ``points`` in the loop's frame; ValueError on the wire."""
        relative = points - self.center_m
        z = relative @ self.axis
        rho_vec = relative - z[..., None] * self.axis
        rho = np.sqrt(np.einsum("...i,...i->...", rho_vec, rho_vec))
        alpha2 = (self.radius_m - rho) ** 2 + z**2
        if np.any(alpha2 < (WIRE_CLEARANCE * self.radius_m) ** 2):
            raise ValueError(
                f"field point within {WIRE_CLEARANCE:g}·R of the loop's wire (R = {self.radius_m} m): "
                "the filament field diverges there"
            )
        return rho_vec, rho, z, alpha2

    def field_t(self, points_m: ArrayLike) -> np.ndarray:
        rho_vec, rho, z, alpha2 = self._cylindrical(as_points_m(points_m))
        big_r = self.radius_m
        beta2 = (big_r + rho) ** 2 + z**2
        m = 4.0 * big_r * rho / beta2
        p = alpha2 / beta2  # 1 − m, without cancellation near the wire
        k_int = ellipkm1(p)
        e_int = ellipe(m)
        with np.errstate(divide="ignore", invalid="ignore"):
            closed = ((1.0 + p) * e_int - 2.0 * p * k_int) / (m * m * p)
        j = np.where(m < 0.5, (3.0 * np.pi / 16.0) * hyp2f1(1.5, 2.5, 3.0, np.minimum(m, 0.5)), closed)
        ni = MU0 * self.turns * self.current_a
        beta = np.sqrt(beta2)
        b_z = ni / (2.0 * np.pi * alpha2 * beta) * (((big_r - rho) * (big_r + rho) - z**2) * e_int + alpha2 * k_int)
        b_rho_over_rho = 4.0 * ni * big_r**2 * z * j / (np.pi * beta2**2 * beta)
        return b_rho_over_rho[..., None] * rho_vec + b_z[..., None] * self.axis

    def _step_m(self, points: np.ndarray, fraction: float) -> np.ndarray:
        return fraction * np.sqrt(self._cylindrical(points)[3])

    def gradient_t_per_m(self, points_m: ArrayLike) -> np.ndarray:
        points = as_points_m(points_m)
        return _central_jacobian(self.field_t, points, self._step_m(points, GRADIENT_STEP))

    def hessian_t_per_m2(self, points_m: ArrayLike) -> np.ndarray:
        points = as_points_m(points_m)
        return _central_jacobian(self.gradient_t_per_m, points, self._step_m(points, HESSIAN_STEP))

    def _params(self) -> dict:
        return {
            "center_m": self.center_m,
            "axis": self.axis,
            "radius_m": self.radius_m,
            "turns": self.turns,
            "current_a": self.current_a,
        }


def _coaxial_pair(
    center_m: ArrayLike, axis: ArrayLike, radius_m: float, turns: float, current_a: float, sign: float
) -> SumSource:
    """Loops at center ± (R/2)·axis, currents I (at +) and sign·I (at −)."""
    axis = unit_vector3("axis", axis)
    center = vector3("center_m", center_m)
    half = 0.5 * positive("radius_m", radius_m) * axis
    return SumSource(
        (
            CurrentLoop(center + half, axis, radius_m, turns, current_a),
            CurrentLoop(center - half, axis, radius_m, turns, sign * current_a),
        )
    )


def helmholtz_pair(center_m: ArrayLike, axis: ArrayLike, radius_m: float, turns: float, current_a: float) -> SumSource:
    """Helmholtz pair: coaxial loops of radius R at ±R/2 along ``axis``, same current.

    The centre field is (4/5)^(3/2)·μ0·N·I/R along ``axis``, flat to fourth order:
    B_z(z)/B_z(0) = 1 − (144/125)(z/R)⁴ + O((z/R)⁶) on the axis.
    """
    return _coaxial_pair(center_m, axis, radius_m, turns, current_a, +1.0)


def anti_helmholtz_pair(
    center_m: ArrayLike, axis: ArrayLike, radius_m: float, turns: float, current_a: float
) -> SumSource:
    """Anti-Helmholtz pair: as :func:`helmholtz_pair` but the loop at −R/2 carries −I.

    B = 0 at the centre, where ∂B_z/∂z = 3μ0NI·R²·d / (2(R² + d²/4)^(5/2)) with d = R,
    i.e. 48/(25√5)·μ0·N·I/R² (positive for I > 0), and G_xx = G_yy = −G_zz/2 about the axis.
    """
    return _coaxial_pair(center_m, axis, radius_m, turns, current_a, -1.0)


def solenoid(
    center_m: ArrayLike,
    axis: ArrayLike,
    radius_m: float,
    length_m: float,
    turns: float,
    current_a: float,
    n_loops: int = 8,
) -> SumSource:
    """A short coil as ``n_loops`` coaxial loops at the midpoints of equal slices of ``length_m``.

    Each loop carries ``turns``/``n_loops`` turns (a layered winding of one radius). With
    ``length_m`` = 0 it is one loop of all the turns.
    """
    axis = unit_vector3("axis", axis)
    length = float(length_m)
    if not (np.isfinite(length) and length >= 0.0):
        raise ValueError(f"length_m must be finite and ≥ 0, got {length_m!r}")
    if int(n_loops) != n_loops or n_loops < 1:
        raise ValueError(f"n_loops must be an integer ≥ 1, got {n_loops!r}")
    n_loops = int(n_loops) if length > 0.0 else 1
    positions = ((np.arange(n_loops) + 0.5) / n_loops - 0.5) * length
    center = vector3("center_m", center_m)
    return SumSource(
        CurrentLoop(center + z * axis, axis, radius_m, positive("turns", turns) / n_loops, current_a) for z in positions
    )
