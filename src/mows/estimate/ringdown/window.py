"""Which samples of a ring-down the fit sees: the longest unsaturated run after the coil
current's decay (:func:`usable_window`), its channels combined as the fit's options say
(:func:`combine_channels`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

# The coil current's decay after switch-off: what the estimator node, `mows fit` and the lab leave
# out of a ring-down (fit_ringdown's ``coil_off_skip_s``; 0 there, for data that start clean).
COIL_OFF_SKIP_S = 0.003


def usable_window(saturated: NDArray[np.bool_], skip_samples: int = 0) -> tuple[int, int]:
    """(start, stop) of the longest run of samples after ``skip_samples`` in which no channel
    is saturated; the coil-on tail and any clipped stretch are thereby excluded."""
    bad = np.asarray(np.asarray(saturated).reshape(len(saturated), -1).any(axis=1))
    bad[:skip_samples] = True
    good = np.concatenate([[False], ~bad, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(good))
    starts, stops = edges[0::2], edges[1::2]
    if starts.size == 0:
        return 0, 0
    longest = np.argmax(stops - starts)
    return int(starts[longest]), int(stops[longest])


def combine_channels(samples: ArrayLike, mode: str) -> NDArray[np.float64]:
    """(C, n) data for the fit: the difference of the pair, one channel, or both."""
    samples = np.asarray(samples, float)
    if samples.ndim == 1:
        return samples[None, :]
    if mode == "difference":
        return (samples[:, 0] - samples[:, 1])[None, :]
    if mode == "channel1":
        return samples[:, 0][None, :]
    if mode == "channel2":
        return samples[:, 1][None, :]
    return samples.T.copy()
