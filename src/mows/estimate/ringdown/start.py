"""Where a ring-down fit starts: the white-noise level from the data alone, and starting points
(f, δ, θmax, φ) from the zero-padded spectrum (the lines at f and 2f; near θ0 = 90° the
signal is mostly at 2f)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import NDArray

from mows.estimate.ringdown.types import FitOptions


def white_noise_std(y: NDArray[np.float64]) -> float:
    """White-noise σ per sample from the third difference, robust to outliers.

    The third difference multiplies a tone at f by (2·sin(πf/fs))³ ≈ 4e-5 for the probe at
    20 kS/s, so the ring-down itself does not leak in, while white noise of variance σ²
    comes out as zero-median noise of variance 20σ² (1² + 3² + 3² + 1²); its median absolute
    value is 0.6745 of its standard deviation.
    """
    third = y[3:] - y[:-3] + 3.0 * (y[1:-2] - y[2:-1])
    return float(np.median(np.abs(third))) / (0.6745 * math.sqrt(20.0))


@dataclasses.dataclass
class Peak:
    frequency_hz: float
    power: float
    phase_rad: float


def windowed_spectrum(
    y: NDArray[np.float64], fs: float, pad: int
) -> tuple[NDArray[np.complex128], NDArray[np.floating]]:
    spectrum = np.fft.rfft((y - y.mean()) * np.hanning(y.size), pad)
    return spectrum, np.fft.rfftfreq(pad, 1.0 / fs)


def spectral_peak(
    spectrum: NDArray[np.complex128],
    power: NDArray[np.float64],
    freqs: NDArray[np.floating],
    low_hz: float,
    high_hz: float,
    bin_hz: float,
) -> Peak | None:
    """Strongest line in [low, high], refined by Gaussian (log-parabolic) interpolation."""
    band = np.flatnonzero((freqs >= low_hz) & (freqs <= high_hz))
    if band.size < 3:
        return None
    k = band[np.argmax(power[band])]
    k = min(max(k, 1), power.size - 2)
    lp = np.log(power[k - 1 : k + 2] + 1e-300)
    denom = lp[0] - 2 * lp[1] + lp[2]
    shift = 0.5 * (lp[0] - lp[2]) / denom if denom < 0 else 0.0
    return Peak(freqs[k] + shift * bin_hz, power[k], float(np.angle(spectrum[k])))


def start_candidates(
    y: NDArray[np.float64], fs: float, expected_hz: float, options: FitOptions, damping_guess: float
) -> list[NDArray[np.float64]]:
    """Starting points (f, δ, θmax, φ) from the spectrum; the best of them is refined."""
    pad = 1 << int(math.ceil(math.log2(4 * y.size)))
    lo, hi = expected_hz * (1 - options.search_fraction), expected_hz * (1 + options.search_fraction)
    spectrum, freqs = windowed_spectrum(y, fs, pad)
    power = np.abs(spectrum) ** 2
    p1 = spectral_peak(spectrum, power, freqs, lo, hi, fs / pad)
    p2 = spectral_peak(spectrum, power, freqs, 2 * lo, 2 * hi, fs / pad)
    floor = np.median(power[1:])
    found = [p for p in (p1, p2) if p is not None and p.power > options.detection_snr * floor]
    if not found:
        return []
    # A line at f fixes φ up to the sign of κ; a line at 2f fixes 2φ up to the sign of its
    # coefficient, which depends on θ0: try every quarter turn and let the data choose.
    starts = []
    if p1 is not None and p1 in found:
        starts += [np.array([p1.frequency_hz, damping_guess, 0.3, p1.phase_rad + k * math.pi]) for k in (0, 1)]
    if p2 is not None and p2 in found:
        starts += [
            np.array([p2.frequency_hz / 2.0, damping_guess, 0.3, p2.phase_rad / 2.0 + k * math.pi / 2])
            for k in range(4)
        ]
    return starts
