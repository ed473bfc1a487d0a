"""The plotted curves, computed from a result's numbers, never refitted.

A ring-down's model is the fitted signal of the estimator (docs/physics.md §6): the deflection
x(t) = θmax·e^(−δt)·cos(2πft + φ) (Eq. S2) seen through the fitted pickup series,
y(t) = κ·Σ_k Re(C_k·e^(ikx)) + B_DC (Eq. S11 with the lever's exact pickup), t from the fit's
first sample. Where the fit leaves θmax undetermined (NaN: the data do not separate it from
κ, docs/physics.md §6), the fits it could not tell apart are drawn by one of them: θmax on a
grid over the fit's range (``SWING_GRID_RAD``), κ and B_DC, linear in the model, by least
squares on the window's samples, the best kept; f, δ, φ and the pickup stay the fit's. A sweep's
curve is its harmonic series Δf(θ0) = Σ_k P_k·cos(kθ0 + φ_k) (Eq. 12).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mows.estimate.ringdown.problem import AMPLITUDE_BOUNDS_RAD
from mows.estimate.ringdown.window import combine_channels

SWING_GRID_RAD = np.geomspace(*AMPLITUDE_BOUNDS_RAD, 64)  # the fit's range of θmax


@dataclass(frozen=True)
class RingdownModel:
    """The numbers of a RingdownFit the model curve needs (SI units; ``pickup`` the C_k)."""

    frequency_hz: float
    damping_per_s: float
    amplitude_rad: float
    phase_rad: float
    kappa_t: float
    offset_t: float
    pickup: tuple[complex, ...]

    @classmethod
    def of(cls, fit) -> RingdownModel:
        """From a RingdownFit message (rclpy's or a bag's)."""
        pickup = tuple(complex(re, im) for re, im in zip(fit.pickup_real, fit.pickup_imag))
        names = ("frequency_hz", "damping_per_s", "amplitude_rad", "phase_rad", "kappa_t", "offset_t")
        return cls(**{name: float(getattr(fit, name)) for name in names}, pickup=pickup)

    @property
    def drawable(self) -> bool:
        """Whether the numbers the curve needs are known, θmax aside (module docstring)."""
        numbers = (self.frequency_hz, self.damping_per_s, self.phase_rad, self.kappa_t, self.offset_t)
        return all(math.isfinite(x) for x in numbers) and bool(self.pickup)

    def deflection_rad(self, t_s: ArrayLike, amplitude_rad: float) -> NDArray[np.float64]:
        """x(t) of the module docstring with the swing ``amplitude_rad``."""
        t = np.asarray(t_s, float)
        return (
            amplitude_rad
            * np.exp(-self.damping_per_s * t)
            * np.cos(2 * math.pi * self.frequency_hz * t + self.phase_rad)
        )

    def series(self, t_s: ArrayLike, amplitude_rad: float) -> NDArray[np.float64]:
        """The pickup series g(x(t)) with the swing ``amplitude_rad``."""
        orders = np.arange(len(self.pickup))
        terms = np.exp(1j * np.multiply.outer(self.deflection_rad(t_s, amplitude_rad), orders))
        # A sum, not ``@``: a threaded BLAS's product waits on threads a loaded host has taken
        # (docs/performance.md, live view).
        return np.real((terms * np.asarray(self.pickup, complex)).sum(axis=-1))

    def completed(self, t_s: ArrayLike, data_t: ArrayLike) -> RingdownModel:
        """This model, or where θmax is NaN the one of the fits it stands for that is nearest
        ``data_t`` (module docstring)."""
        if math.isfinite(self.amplitude_rad):
            return self
        t, y = np.asarray(t_s, float), np.asarray(data_t, float)
        kept = np.isfinite(y)
        best = (math.inf, self)
        for swing in SWING_GRID_RAD:
            design = np.column_stack([self.series(t[kept], swing), np.ones(kept.sum())])
            (kappa, offset), *_ = np.linalg.lstsq(design, y[kept], rcond=None)
            cost = float(np.sum((design @ (kappa, offset) - y[kept]) ** 2))
            if cost < best[0]:
                best = (cost, dataclasses.replace(self, amplitude_rad=swing, kappa_t=kappa, offset_t=offset))
        return best[1]

    def signal_t(self, t_s: ArrayLike) -> NDArray[np.float64]:
        """y(t) of the module docstring, tesla, at times ``t_s`` from the fit's first sample."""
        return self.kappa_t * self.series(t_s, self.amplitude_rad) + self.offset_t


@dataclass(frozen=True)
class RingdownCurve:
    """A ring-down's data, model and residual (data − model), tesla, at ``t_s`` from its first sample."""

    t_s: NDArray[np.float64]
    data_t: NDArray[np.float64]
    model_t: NDArray[np.float64]

    @property
    def residual_t(self) -> NDArray[np.float64]:
        return self.data_t - self.model_t


def ringdown_curve(
    samples_t: ArrayLike, sample_rate_hz: float, model: RingdownModel, channels: str = "difference", every: int = 1
) -> RingdownCurve:
    """The fitted window's samples (rows: samples, columns: the fluxgates) combined as the fit
    combined them (``channels``, :func:`mows.estimate.ringdown.window.combine_channels`; one
    channel: 'difference', 'channel1' or 'channel2'), beside the model of ``model``; only every
    ``every``-th sample, the plotted ones: the model is computed at those alone (where θmax is
    undetermined, its grid of least squares costs seconds over a whole window under load)."""
    if channels == "both":
        raise ValueError("channels = 'both': a fit of both channels has a κ per channel; draw one channel")
    data = combine_channels(samples_t, channels)[0][::every]
    t_s = np.arange(data.size) * every / sample_rate_hz
    return RingdownCurve(t_s, data, model.completed(t_s, data).signal_t(t_s))


def sweep_curve_hz(harmonic_amplitude_hz: ArrayLike, harmonic_phase_rad: ArrayLike, theta0_rad: ArrayLike) -> NDArray:
    """Δf(θ0) = Σ_k P_k·cos(kθ0 + φ_k), Hz (Eq. 12), k = 0, 1, …"""
    amplitude, phase = np.asarray(harmonic_amplitude_hz, float), np.asarray(harmonic_phase_rad, float)
    theta = np.asarray(theta0_rad, float)
    k = np.arange(amplitude.size)
    return np.cos(np.multiply.outer(theta, k) + phase) @ amplitude


def stride(n: int, max_points: int) -> int:
    """The step that keeps at most ``max_points`` of ``n`` evenly spaced points."""
    if max_points < 1:
        raise ValueError(f"max_points = {max_points} must be at least 1")
    return max(1, math.ceil(n / max_points))
