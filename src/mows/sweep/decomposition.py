"""What a rotation sweep's decomposition reports: its harmonic content (Eq. 12), the in-plane
field and gradient with their covariance, or why there are none (:mod:`mows.sweep.decompose`)."""

from __future__ import annotations

import dataclasses
import enum
import math

import numpy as np

from mows.sweep.shift_model import PARAMETER_COUNT


@dataclasses.dataclass(frozen=True)
class Harmonics:
    """Δf = Σ_k P_k·cos(k·θ0 + φ_k), k = 0 … K, by weighted linear least squares (Eq. 12)."""

    amplitude_hz: np.ndarray
    phase_rad: np.ndarray
    cosine_hz: np.ndarray  # a_k of Σ a_k cos kθ0 + b_k sin kθ0
    sine_hz: np.ndarray  # b_k
    covariance: np.ndarray  # of (a_0, a_1, b_1, …)


def fit_harmonics(theta0_rad, shift_hz, shift_std_hz, max_order: int = 2) -> Harmonics:
    """Harmonic content of a sweep up to ``max_order`` (limited by the number of angles)."""
    theta0 = np.asarray(theta0_rad, float)
    columns = [np.ones_like(theta0)]
    for k in range(1, max_order + 1):
        columns += [np.cos(k * theta0), np.sin(k * theta0)]
    design = np.stack(columns, axis=1) / np.asarray(shift_std_hz, float)[:, None]
    coef, *_ = np.linalg.lstsq(design, np.asarray(shift_hz, float) / shift_std_hz, rcond=None)
    covariance = np.linalg.pinv(design.T @ design)
    a = np.concatenate([[coef[0]], coef[1::2]])
    b = np.concatenate([[0.0], coef[2::2]])
    # P·cos(kθ + φ) = P·cos φ·cos kθ − P·sin φ·sin kθ, so a = P·cos φ and b = −P·sin φ.
    return Harmonics(np.hypot(a, b), np.arctan2(-b, a), a, b, covariance)


class DecompositionStatus(enum.IntEnum):
    """Why a sweep gave no field and gradient; the number is SweepDecomposition's ``status``
    (0 OK, otherwise see ``message``)."""

    OK = 0
    INVALID_INPUT = 1  # unequal lengths, non-finite values, σ ≤ 0
    TOO_FEW_ORIENTATIONS = 2  # fewer distinct θ0 than the model's harmonics need
    NOT_CONVERGED = 3
    NO_DECOMPOSITION = 4  # the sweep ended before one (cancelled, no usable ring-down)


@dataclasses.dataclass
class Decomposition:
    """In-plane field and gradient of one sweep, SI units; NaN unless ``ok``."""

    model: str
    status: DecompositionStatus
    message: str
    field_t: np.ndarray = dataclasses.field(default_factory=lambda: np.full(2, np.nan))
    field_covariance_t2: np.ndarray = dataclasses.field(default_factory=lambda: np.full((2, 2), np.nan))
    gradient_t_per_m: np.ndarray = dataclasses.field(default_factory=lambda: np.full(3, np.nan))  # Gxx, Gxy, Gyy
    gradient_covariance: np.ndarray = dataclasses.field(default_factory=lambda: np.full((3, 3), np.nan))
    f00_hz: float = math.nan
    f00_free: bool = False
    harmonics: Harmonics | None = None
    chi2_dof: float = math.nan
    rms_residual_hz: float = math.nan
    residual_hz: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    # Bx, By, Gs, Gd, Gxy, Δf00, Hc, Hs (the field's in-plane 3θ0 curvature, T/m², 0 unless fitted)
    parameters: np.ndarray = dataclasses.field(default_factory=lambda: np.full(PARAMETER_COUNT, np.nan))
    # σ of (Bx, By, Gxx, Gxy, Gyy) from the errors shared by every ring-down (the calibrated f00,
    # the stop): their part of the covariance, which no number of ring-downs reduces
    shared_std: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(5))

    @property
    def ok(self) -> bool:
        return self.status is DecompositionStatus.OK

    def _chi2_text(self) -> str:
        """χ²/dof, or why there is none: as many free coefficients as orientations fit exactly."""
        if math.isfinite(self.chi2_dof):
            return f"χ²/dof = {self.chi2_dof:.2f}"
        return "χ²/dof not determined (0 degrees of freedom: as many orientations as free coefficients)"

    def report(self) -> str:
        if not self.ok:
            return f"sweep decomposition ({self.model}): {self.status.name}: {self.message}"
        sb = np.sqrt(np.diag(self.field_covariance_t2))
        sg = np.sqrt(np.diag(self.gradient_covariance))
        bx, by = self.field_t * 1e6
        gxx, gxy, gyy = self.gradient_t_per_m * 1e3
        return (
            f"{self.model}: B = ({bx:.3f} ± {sb[0] * 1e6:.3f}, {by:.3f} ± {sb[1] * 1e6:.3f}) µT, "
            f"|B| = {math.hypot(bx, by):.3f} µT at {math.degrees(math.atan2(by, bx)):.1f}°; "
            f"G = (xx {gxx:.3f} ± {sg[0] * 1e3:.3f}, xy {gxy:.3f} ± {sg[1] * 1e3:.3f}, "
            f"yy {gyy:.3f} ± {sg[2] * 1e3:.3f}) mT/m; {self._chi2_text()}, "
            f"rms residual {self.rms_residual_hz * 1e3:.3f} mHz"
        )
