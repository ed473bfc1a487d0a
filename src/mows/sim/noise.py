"""Fluxgate noise as a continuous stream across blocks (:class:`NoiseStream`) for the simulated device."""

from __future__ import annotations

import math

import numpy as np
from scipy import signal as sp_signal

# 1/f noise: pole–zero pairs spaced 2 per decade from PINK_LOW_HZ up (NoiseStream).
PINK_LOW_HZ = 0.01
PINK_POLES_PER_DECADE = 2


class NoiseStream:
    """:class:`mows.physics.fluxgate.NoiseModel` noise, continuous across blocks.

    Every sample consumes four standard normals in order (common white, 1/f driver, sensor 1,
    sensor 2), so the stream does not depend on how it is cut into blocks. The 1/f part is
    white noise through a fixed filter of real pole–zero pairs spaced
    :data:`PINK_POLES_PER_DECADE` per decade from :data:`PINK_LOW_HZ` to fs/2 (each zero half
    a spacing above its pole: on average −10 dB/decade, within 0.05 dB of 1/f from 0.1 Hz to
    1 kHz, flat below 0.01 Hz), mapped to the sampled domain by z = e^(−2πf/fs) and scaled to
    the model's ASD at 1 Hz. Its state is
    carried from block to block, so the 1/f noise has no discontinuity at block edges; it
    starts at rest, so its content below ~0.1 Hz builds up over the first ~10 s (a slow
    offset, which the ring-down fit absorbs anyway). Mains hum is a sine of device time.
    """

    def __init__(self, model, sample_rate_hz: float, rng: np.random.Generator):
        self.model = model
        self.sample_rate_hz = float(sample_rate_hz)
        self.rng = rng
        self._mains_phase = rng.uniform(0.0, math.tau)
        self._sos, self._pink_gain = pink_filter(self.sample_rate_hz, model.common_pink_t_per_rthz_at_1hz)
        self._state = np.zeros((self._sos.shape[0], 2))

    def draw(self, first_index: int, n: int) -> np.ndarray:
        """Noise of samples first_index … first_index + n − 1 of both channels, tesla, (n, 2)."""
        m = self.model
        silent = not (
            m.common_white_t_per_rthz or m.common_pink_t_per_rthz_at_1hz or m.sensor_white_t_per_rthz or m.mains_t
        )
        if silent or n == 0:
            return np.zeros((n, 2))  # nothing to draw
        normals = self.rng.standard_normal((n, 4))
        white_scale = math.sqrt(self.sample_rate_hz / 2.0)  # per-sample σ of a one-sided ASD of 1
        pink, self._state = sp_signal.sosfilt(self._sos, normals[:, 1], zi=self._state)
        t = (first_index + np.arange(n)) / self.sample_rate_hz
        common = (
            m.common_white_t_per_rthz * white_scale * normals[:, 0]
            + self._pink_gain * pink
            + m.mains_t * np.sin(math.tau * m.mains_hz * t + self._mains_phase)
        )
        return common[:, None] + m.sensor_white_t_per_rthz * white_scale * normals[:, 2:]


def pink_filter(sample_rate_hz: float, asd_at_1hz_t_per_rthz: float):
    """(sos, gain): unit white noise through ``sos`` × gain has one-sided ASD asd·(f/1 Hz)^(−1/2)."""
    spacing = 10.0 ** (1.0 / PINK_POLES_PER_DECADE)
    n_pairs = int(math.ceil(math.log10(sample_rate_hz / 2.0 / PINK_LOW_HZ) * PINK_POLES_PER_DECADE))
    poles_hz = PINK_LOW_HZ * spacing ** np.arange(n_pairs)
    zeros_hz = poles_hz * math.sqrt(spacing)
    sos = sp_signal.zpk2sos(
        np.exp(-math.tau * zeros_hz / sample_rate_hz), np.exp(-math.tau * poles_hz / sample_rate_hz), 1.0
    )
    _, response = sp_signal.sosfreqz(sos, worN=[1.0], fs=sample_rate_hz)
    # Unit white noise has one-sided PSD 2/fs; the gain makes the output's PSD asd² at 1 Hz.
    return sos, asd_at_1hz_t_per_rthz * math.sqrt(sample_rate_hz / 2.0) / abs(response[0])
