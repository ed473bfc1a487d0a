"""The published frequency model (Eqs. 1, 4-8, 11-12, S13-S24) and its exact inverses.

``k = kM + kB + kG`` with ``kB = m·Bx'`` (Eq. 4) and ``kG = l·m·Gx'x'`` (Eq. 5), and
``Δf = f00·(√(1 + (kB + kG)/kM) − 1)`` (Eq. 6). This is the model the paper fits; the
physics it leaves out is in :mod:`mows.physics.potential` and the model lab.

Corrections to the paper (docs/physics.md §8): the Taylor form of the rotation sweep (Eq. 11 and
the supplement's decomposition section) lacks the factor f00; here it has it. All
functions accept numpy arrays and broadcast.

Numerics: ``√(1+u) − 1`` is evaluated as ``u / (√(1+u) + 1)``, which keeps full relative
precision at the sub-nanotesla shifts the probe resolves (u ~ 1e-8).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mows.physics.schema import FloatOrArray, Vector


def field_spring_nm_per_rad(moment_am2: FloatOrArray, field_t: FloatOrArray) -> FloatOrArray:
    """Magnetic field spring kB = m·Bx', N·m/rad (Eq. 4, small deflection)."""
    return np.multiply(moment_am2, field_t)


def gradient_spring_nm_per_rad(
    moment_am2: FloatOrArray, lever_m: FloatOrArray, gradient_t_per_m: FloatOrArray
) -> FloatOrArray:
    """Gradient spring kG = l·m·Gx'x', N·m/rad (Eq. 5, small deflection)."""
    return np.multiply(np.multiply(lever_m, moment_am2), gradient_t_per_m)


def _sqrt1p_minus_1(u: FloatOrArray) -> np.ndarray:
    """√(1+u) − 1 without cancellation; NaN where 1 + u < 0 (no real frequency)."""
    u = np.asarray(u, dtype=float)
    root = np.sqrt(np.where(u >= -1.0, 1.0 + u, np.nan))
    return u / (root + 1.0)


def frequency_shift_hz(
    f00_hz: FloatOrArray, spring_nm_per_rad: FloatOrArray, magnetic_spring_nm_per_rad: FloatOrArray
) -> FloatOrArray:
    """Δf = f00·(√(1 + (kB + kG)/kM) − 1), Hz (Eq. 6); NaN beyond spring cancellation."""
    return np.multiply(f00_hz, _sqrt1p_minus_1(np.divide(magnetic_spring_nm_per_rad, spring_nm_per_rad)))


def field_sensitivity_hz_per_t(
    field_t: FloatOrArray, f00_hz: FloatOrArray, spring_nm_per_rad: FloatOrArray, moment_am2: FloatOrArray
) -> FloatOrArray:
    """β = Δf_B,0 / B, Hz/T (Eq. 7), exact and continuous through B = 0.

    β = f00·(m/kM) / (√(1 + m·B/kM) + 1), whose B → 0 limit is Eq. 9, f00·m/(2kM).
    """
    ratio = np.divide(moment_am2, spring_nm_per_rad)
    root = np.sqrt(np.where(1.0 + ratio * np.asarray(field_t) >= 0, 1.0 + ratio * np.asarray(field_t), np.nan))
    return np.multiply(f00_hz, ratio) / (root + 1.0)


def gradient_sensitivity_hz_m_per_t(
    gradient_t_per_m: FloatOrArray,
    f00_hz: FloatOrArray,
    spring_nm_per_rad: FloatOrArray,
    moment_am2: FloatOrArray,
    lever_m: FloatOrArray,
) -> FloatOrArray:
    """γ = Δf_0,G / G, Hz·m/T (Eq. 8); γ → β0·l as G → 0."""
    return np.multiply(
        lever_m,
        field_sensitivity_hz_per_t(np.multiply(lever_m, gradient_t_per_m), f00_hz, spring_nm_per_rad, moment_am2),
    )


def weak_field_sensitivity_hz_per_t(
    f00_hz: FloatOrArray, spring_nm_per_rad: FloatOrArray, moment_am2: FloatOrArray
) -> FloatOrArray:
    """β0 = lim_{B→0} β = f00·m/(2kM), Hz/T (Eq. 9)."""
    return np.multiply(f00_hz, moment_am2) / (2.0 * np.asarray(spring_nm_per_rad))


def spring_ratio_from_shift(frequency_shift_hz_: FloatOrArray, f00_hz: FloatOrArray) -> FloatOrArray:
    """(k − kM)/kM = (1 + Δf/f00)² − 1 = r·(2 + r), r = Δf/f00: Eq. 6 solved exactly."""
    r = np.divide(frequency_shift_hz_, f00_hz)
    return r * (2.0 + r)


@dataclasses.dataclass(frozen=True)
class Inversion:
    """A value inferred from a frequency shift, with its standard uncertainty (SI units)."""

    value: np.ndarray
    std: np.ndarray


def field_from_shift_t(
    frequency_shift_hz_: FloatOrArray,
    f00_hz: FloatOrArray,
    spring_nm_per_rad: FloatOrArray,
    moment_am2: FloatOrArray,
    frequency_shift_std_hz: FloatOrArray = 0.0,
) -> Inversion:
    """Field along the probe axis from Δf assuming G = 0: B = (kM/m)·((1 + Δf/f00)² − 1).

    Exact inverse of Eq. 6 with kG = 0. The uncertainty is propagated to first order,
    σ_B = (kM/m)·2(1 + Δf/f00)/f00 · σ_Δf; Eq. 6 is quadratic in (1 + Δf/f00), so the
    neglected term is (σ_Δf/f00)² relative, below 1e-10 for any usable ring-down.
    Returns NaN for Δf ≤ −f00 (no oscillation).
    """
    return _invert(frequency_shift_hz_, f00_hz, np.divide(spring_nm_per_rad, moment_am2), frequency_shift_std_hz)


def gradient_from_shift_t_per_m(
    frequency_shift_hz_: FloatOrArray,
    f00_hz: FloatOrArray,
    spring_nm_per_rad: FloatOrArray,
    moment_am2: FloatOrArray,
    lever_m: FloatOrArray,
    frequency_shift_std_hz: FloatOrArray = 0.0,
) -> Inversion:
    """Gradient Gx'x' from Δf assuming B = 0: G = (kM/(l·m))·((1 + Δf/f00)² − 1) (Eq. S24).

    Eq. S24 writes G = (4π²(f00 + Δf)²·J − kM)/(l·m); with J = kM/(2π·f00)² (Eq. 10)
    that is this expression. Same error propagation as :func:`field_from_shift_t`.
    """
    return _invert(
        frequency_shift_hz_,
        f00_hz,
        np.divide(spring_nm_per_rad, np.multiply(moment_am2, lever_m)),
        frequency_shift_std_hz,
    )


def _invert(shift_hz: FloatOrArray, f00_hz: FloatOrArray, scale: FloatOrArray, shift_std_hz: FloatOrArray) -> Inversion:
    shift_hz = np.asarray(shift_hz, dtype=float)
    valid = shift_hz > -np.asarray(f00_hz)
    value = np.where(valid, scale * spring_ratio_from_shift(shift_hz, f00_hz), np.nan)
    slope = scale * 2.0 * (1.0 + shift_hz / f00_hz) / f00_hz
    std = np.where(valid, np.abs(slope) * np.asarray(shift_std_hz, dtype=float), np.nan)
    return Inversion(value=value, std=std)


@dataclasses.dataclass(frozen=True)
class PublishedSweep:
    """The published rotation-sweep model of an in-plane field (Bx, By), T, and gradient
    (Gxx, Gxy, Gyy), T/m (G_ij = ∂B_i/∂x_j, symmetric), for a probe of f00, kM, m and l."""

    field_xy_t: Vector
    gradient_xy_t_per_m: Vector
    f00_hz: float
    spring_nm_per_rad: float
    moment_am2: float
    lever_m: float

    def shift_hz(self, theta0_rad: FloatOrArray, exact: bool = True) -> FloatOrArray:
        """Δf(θ0) at the orientations ``theta0_rad`` (Eqs. 6, 11, S18).

        The probe axis is x' = (cos θ0, sin θ0); kB = m·Bx', kG = l·m·Gx'x' with
        Gx'x' = x'ᵀ·G·x'. With ``exact`` the √ of Eq. 6 is kept; otherwise the first-order
        form Δf = f00·(kB + kG)/(2kM) of Eq. 11, corrected by the factor f00 (docs/physics.md §8).
        """
        theta0 = np.asarray(theta0_rad, dtype=float)
        c, s = np.cos(theta0), np.sin(theta0)
        bx, by = self.field_xy_t
        gxx, gxy, gyy = self.gradient_xy_t_per_m
        field_along = bx * c + by * s
        gradient_along = gxx * c * c + 2.0 * gxy * c * s + gyy * s * s
        k_mag = field_spring_nm_per_rad(self.moment_am2, field_along) + gradient_spring_nm_per_rad(
            self.moment_am2, self.lever_m, gradient_along
        )
        if exact:
            return frequency_shift_hz(self.f00_hz, self.spring_nm_per_rad, k_mag)
        return np.multiply(self.f00_hz, k_mag) / (2.0 * self.spring_nm_per_rad)

    def harmonics(self) -> dict[str, float]:
        """Prefactors of Eq. 12, Δf ≈ P0 + P1·cos(θ0 + φ1) + P2·cos(2θ0 + φ2), first order.

        P1 = f00·m·|B|/(2kM), φ1 = −atan2(By, Bx); the gradient gives the constant
        P0 = f00·l·m·(Gxx + Gyy)/(4kM) and P2 = f00·l·m·|((Gxx − Gyy)/2, Gxy)|/(2kM),
        φ2 = −atan2(Gxy, (Gxx − Gyy)/2). Returns a dict with P0_hz, P1_hz, phi1_rad, P2_hz, phi2_rad.
        """
        bx, by = self.field_xy_t
        gxx, gxy, gyy = self.gradient_xy_t_per_m
        scale = self.f00_hz * self.moment_am2 / (2.0 * self.spring_nm_per_rad)
        half_diff = 0.5 * (gxx - gyy)
        return {
            "P0_hz": scale * self.lever_m * 0.5 * (gxx + gyy),
            "P1_hz": scale * np.hypot(bx, by),
            "phi1_rad": -np.arctan2(by, bx),
            "P2_hz": scale * self.lever_m * np.hypot(half_diff, gxy),
            "phi2_rad": -np.arctan2(gxy, half_diff),
        }
