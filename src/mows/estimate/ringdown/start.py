"""Where a ring-down fit starts: the white-noise level from the data alone, and each tone's
starting (f, φ) from the zero-padded spectrum.

The lines at f are found one at a time: the strongest peak of the spectrum of what is left in
the tones' bands, refined by Gaussian interpolation, its damped sinusoid fitted and subtracted
(a line of a strong probe would otherwise hide a weak neighbour's in its skirt). The lines are
assigned to the tones in order of frequency. A tone whose line at f is not found is looked for
at 2f in what is left (near θ0 = 90° its signal is mostly there); one found nowhere starts at
its expected frequency.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from mows.estimate.ringdown.types import FitOptions, ProbeLine


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


def line_starts(
    y: NDArray[np.float64], fs: float, lines: Sequence[ProbeLine], options: FitOptions
) -> list[list[tuple[float, float]]] | None:
    """Each tone's candidate starts (f, φ), in the order of ``lines``, from the spectrum of the
    summed channels ``y`` (module docstring); None where no tone's line stands above the noise
    floor by ``options.detection_snr``. A line at f fixes φ up to the sign of κ: φ and φ + π.
    A line at 2f fixes 2φ up to the sign of its coefficient, which depends on θ0: every quarter
    turn. The data choose among them."""
    residual = np.asarray(y, float) - float(np.mean(y))
    t = np.arange(residual.size) / fs
    pad = 1 << int(math.ceil(math.log2(4 * residual.size)))
    bands = [line.expected_frequency_hz * (1 + options.search_fraction * np.array([-1.0, 1.0])) for line in lines]
    spectrum, freqs = windowed_spectrum(residual, fs, pad)
    power = np.abs(spectrum) ** 2
    threshold = options.detection_snr * float(np.median(power[1:]))  # the data's floor, before any line is taken out
    found: list[tuple[float, float]] = []
    guess = float(np.mean([line.damping_guess_per_s for line in lines]))
    for round_ in range(len(lines)):
        if round_ > 0:
            spectrum, freqs = windowed_spectrum(residual, fs, pad)
            power = np.abs(spectrum) ** 2
        peaks = [spectral_peak(spectrum, power, freqs, low, high, fs / pad) for low, high in bands]
        peak = max((p for p in peaks if p is not None), key=lambda p: p.power, default=None)
        if peak is None or not peak.power > threshold:
            break
        # The line's damped sinusoid, fitted and taken out, so that the next is found beside it.
        carrier = np.exp((-guess + 1j * math.tau * peak.frequency_hz) * t)
        a, b = np.linalg.lstsq(np.column_stack([carrier.real, carrier.imag]), residual, rcond=None)[0]
        found.append((peak.frequency_hz, float(np.angle(complex(a, -b)))))
        residual = residual - (complex(a, -b) * carrier).real
    # Where a tone is left without a line, the loop stopped on the spectrum of what is left.
    starts = _assigned(found, lines)
    candidates: list[list[tuple[float, float]]] = []
    for (low, high), start in zip(bands, starts):
        if start is not None:
            candidates.append([(start[0], start[1] + k * math.pi) for k in (0, 1)])
            continue
        double = spectral_peak(spectrum, power, freqs, 2 * low, 2 * high, fs / pad)
        if double is not None and double.power > threshold:
            f, half = double.frequency_hz / 2.0, double.phase_rad / 2.0
            candidates.append([(f, half + k * math.pi / 2) for k in range(4)])
        else:
            candidates.append([])
    if not any(candidates):
        return None
    return [c or [(line.expected_frequency_hz, k * math.pi) for k in (0, 1)] for c, line in zip(candidates, lines)]


def _assigned(found: list[tuple[float, float]], lines: Sequence[ProbeLine]) -> list[tuple[float, float] | None]:
    """The found lines given to the tones in order of frequency; where fewer lines were found,
    each goes to the tone expected nearest it, the others get None."""
    starts: list[tuple[float, float] | None] = [None] * len(lines)
    if len(found) == len(lines):
        order = np.argsort([line.expected_frequency_hz for line in lines])
        for tone, line in zip(order, sorted(found)):
            starts[tone] = line
        return starts
    free = set(range(len(lines)))
    for f, phase in found:
        nearest = min(free, key=lambda i: abs(lines[i].expected_frequency_hz - f))
        starts[nearest] = (f, phase)
        free.discard(nearest)
    return starts
