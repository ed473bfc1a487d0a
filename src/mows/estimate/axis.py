"""What one ring-down says about the field and gradient along the probe axis.

A single frequency cannot separate field from gradient (Eq. 6: their springs add). The two
numbers reported here are each the value that would explain the whole shift alone: the field
B_x' assuming G = 0 (Eq. 6 inverted), and the gradient G_x'x' assuming B = 0 (Eq. S24).
A rotation sweep (:mod:`mows.sweep.decompose`) separates them.
"""

from __future__ import annotations

import dataclasses
import math

from mows.estimate.ringdown import FitStatus, RingdownFit
from mows.physics.frequency import field_from_shift_t, gradient_from_shift_t_per_m
from mows.physics.probe import Probe

ASSUMPTIONS = (
    "published model, Eq. 6 inverted exactly: field assumes G = 0, gradient (Eq. S24) "
    "assumes B = 0; small-amplitude spring; f00 from calibration"
)


@dataclasses.dataclass(frozen=True)
class AxisEstimate:
    """Field and gradient-equivalent along the probe axis x', SI units; NaN unless OK."""

    status: FitStatus
    message: str
    theta0_rad: float
    frequency_shift_hz: float = math.nan
    frequency_shift_std_hz: float = math.nan
    field_along_axis_t: float = math.nan
    field_along_axis_std_t: float = math.nan
    gradient_equivalent_t_per_m: float = math.nan
    gradient_equivalent_std_t_per_m: float = math.nan
    assumptions: str = ASSUMPTIONS

    @property
    def ok(self) -> bool:
        return self.status == FitStatus.OK


def estimate_along_axis(fit: RingdownFit, probe: Probe, f00_hz: float, f00_std_hz: float = 0.0) -> AxisEstimate:
    """Invert a ring-down fit for B_x' and G_x'x' (Eqs. 6, S24) with propagated uncertainty.

    Δf = f − f00. The inversion X = s·((f/f00)² − 1) depends on f and on f00, with
    ∂X/∂f = 2s·f/f00² and ∂X/∂f00 = −2s·f²/f00³; both uncertainties are propagated (they
    are independent: f00 comes from an earlier calibration). ``s`` is kM/m for the field and
    kM/(l·m) for the gradient.
    """
    if not fit.ok:
        return AxisEstimate(fit.status, fit.message, fit.theta0_rad)
    if not (math.isfinite(f00_hz) and f00_hz > 0 and math.isfinite(f00_std_hz) and f00_std_hz >= 0):
        return AxisEstimate(
            FitStatus.BAD_FIT, f"calibrated f00 = {f00_hz!r} ± {f00_std_hz!r} Hz is not usable", fit.theta0_rad
        )
    f = fit.frequency_hz
    shift = f - f00_hz
    # ∂X/∂f00 = −(f/f00)·∂X/∂f, so both enter through the slope of Eq. 6's inverse.
    effective_std = math.hypot(fit.frequency_std_hz, f / f00_hz * f00_std_hz)
    field = field_from_shift_t(shift, f00_hz, probe.spring_nm_per_rad, probe.moment_am2, effective_std)
    gradient = gradient_from_shift_t_per_m(
        shift, f00_hz, probe.spring_nm_per_rad, probe.moment_am2, probe.lever_m, effective_std
    )
    return AxisEstimate(
        status=FitStatus.OK,
        message="",
        theta0_rad=fit.theta0_rad,
        frequency_shift_hz=shift,
        frequency_shift_std_hz=math.hypot(fit.frequency_std_hz, f00_std_hz),
        field_along_axis_t=float(field.value),
        field_along_axis_std_t=float(field.std),
        gradient_equivalent_t_per_m=float(gradient.value),
        gradient_equivalent_std_t_per_m=float(gradient.std),
    )
