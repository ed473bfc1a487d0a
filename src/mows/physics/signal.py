"""Magnetometer signal of the ringing probe (Eqs. S2, S8–S12).

The moment turns through θ = θ0 + θt with θt = θmax·cos(2πft + φ)·e^(−δt) (Eq. S2). A
single-axis sensor along (a, b, c) on the probe's axis line reads
S = κ·(2a·cos θ − b·sin θ) + B_DC (Eq. S11); the paper's sensors have b = 1 (Eq. S12).
The exact field of the moving magnet at a real sensor is in :mod:`mows.physics.fluxgate`; this
module is the fit model.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from mows.physics.schema import FloatOrArray
from mows.physics.sources import MU0_OVER_4PI


def effective_distance_m(distance_m: FloatOrArray, spacing_m: FloatOrArray) -> FloatOrArray:
    """Differential effective distance r_eff = (1/r³ − 1/(r + d)³)^(−1/3), m (Eq. S10)."""
    r = np.asarray(distance_m, float)
    return (r**-3 - (r + spacing_m) ** -3) ** (-1.0 / 3.0)


def kappa_t(moment_am2: FloatOrArray, distance_m: FloatOrArray) -> FloatOrArray:
    """Signal prefactor κ = μ0·m/(4π·r³), tesla (Eq. S11; pass r_eff for a differential pair)."""
    return MU0_OVER_4PI * np.asarray(moment_am2, float) / np.asarray(distance_m, float) ** 3


def ringdown_angle_rad(
    t_s: ArrayLike,
    amplitude_rad: FloatOrArray,
    frequency_hz: FloatOrArray,
    phase_rad: FloatOrArray,
    damping_per_s: FloatOrArray,
) -> np.ndarray:
    """Free ring-down deflection θt = θmax·cos(2πft + φ)·e^(−δt), rad (Eq. S2)."""
    t = np.asarray(t_s, float)
    return amplitude_rad * np.cos(2.0 * np.pi * frequency_hz * t + phase_rad) * np.exp(-damping_per_s * t)


def signal_t(
    t_s: ArrayLike,
    theta0_rad: FloatOrArray,
    amplitude_rad: FloatOrArray,
    frequency_hz: FloatOrArray,
    phase_rad: FloatOrArray,
    damping_per_s: FloatOrArray,
    kappa: FloatOrArray,
    a: float = 0.0,
    b: float = 1.0,
    offset_t: FloatOrArray = 0.0,
) -> np.ndarray:
    """Sensor reading S = 2a·κ·cos θ − b·κ·sin θ + B_DC, tesla (Eq. S11; Eq. S12 for a=0, b=1)."""
    theta = theta0_rad + ringdown_angle_rad(t_s, amplitude_rad, frequency_hz, phase_rad, damping_per_s)
    return kappa * (2.0 * a * np.cos(theta) - b * np.sin(theta)) + offset_t


def peak_amplitude(theta0_rad: float, amplitude_rad: float) -> float:
    """Half the peak-to-peak swing of −sin(θ0 + x) for x in [−θmax, θmax], in units of κ.

    Exact. At θ0 = 0 it is sin θmax (Eq. 2); at θ0 = 90° it is (1 − cos θmax)/2 ≈ θmax²/4,
    half of the paper's Eq. 3 (docs/physics.md §3), so the 0°:90° ratio at θmax = 15° is 15.19.
    """
    # The extremes of a sine on an interval are at its ends or at an interior crest.
    crests = np.pi / 2 + np.pi * np.arange(-4, 5) - theta0_rad
    inside = crests[np.abs(crests) <= amplitude_rad]
    x = np.concatenate([[-amplitude_rad, amplitude_rad], inside])
    candidates = -np.sin(theta0_rad + x)
    return float(0.5 * (candidates.max() - candidates.min()))
