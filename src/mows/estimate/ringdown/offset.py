"""The rest offset ε and the swing θmax of the ring-down of one probe, searched over their whole range.

With f, δ and φ held (the spectral and local stages find them well: they are nearly orthogonal
to ε and θmax), the model of one channel is linear in the pickup's turned coefficients:

    g(ε + x) = Σ_k Re(C_k·e^(ikε))·cos(kx) − Im(C_k·e^(ikε))·sin(kx) + Re C_0,

so for each θmax on a grid one pass over the data gives the Gram matrix of the 2K columns
cos(kx), sin(kx) (centred: B_DC is free) and their products with the data (those of −θmax
follow by turning the sines over), and then the
variable-projection cost, ‖y‖² − (yᵀs)²/‖s‖² with s the model shape, of every ε on a grid costs
a 2K-vector each. The cost over (θmax, ε) has several minima in a strong field: near θ0 = 90°
the signal is nearly even in ε + x, and κ trades off against θmax. A local fit lands in
whichever its start is nearest (θmax 5.9° where the swing was 12.8°, ε −5.7° for a true
−11.3°); this search hands the fit the start of every distinct minimum instead.

κ > 0 is imposed: the pickup series is normalised by the κ of Eq. S11 for the fit's channel
combination (:func:`mows.physics.fluxgate.pickup_harmonics`), which is positive, and a negative
κ would turn g(ε + x) into −g, the same waveform as a pickup turned by another ε.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mows.estimate.ringdown.problem import RingdownProblem

OFFSET_STEP_RAD = math.radians(1.0)
AMPLITUDE_STEP_RAD = math.radians(1.0)


def _shape_columns(
    problem: RingdownProblem, q: NDArray[np.float64], amplitudes_rad: NDArray[np.float64]
) -> NDArray[np.float64]:
    """cos(kx), sin(kx) for k = 1 … K at every sample: (A, 2K, n) for each θmax."""
    t = np.arange(problem.y.shape[1]) * problem.dt
    base = np.exp(-q[1] * t) * np.cos(math.tau * q[0] * t + q[3])
    x = amplitudes_rad[:, None] * base[None, :]
    order = problem.pickups.shape[1] - 1
    columns = np.empty((x.shape[0], 2 * order, x.shape[1]))
    cos_x, sin_x = np.cos(x), np.sin(x)
    columns[:, 0], columns[:, order] = cos_x, sin_x
    for k in range(1, order):  # cos and sin of (k + 1)x by the angle-addition recurrence
        columns[:, k] = columns[:, k - 1] * cos_x - columns[:, order + k - 1] * sin_x
        columns[:, order + k] = columns[:, order + k - 1] * cos_x + columns[:, k - 1] * sin_x
    return columns


def _weights(pickup: NDArray[np.complex128], offsets_rad: ArrayLike) -> NDArray[np.float64]:
    """The columns' coefficients for each ε: (E, 2K), Re and −Im of C_k·e^(ikε), k ≥ 1."""
    k = np.arange(1, pickup.size)
    turned = pickup[None, 1:] * np.exp(1j * k[None, :] * np.asarray(offsets_rad)[:, None])
    return np.concatenate([turned.real, -turned.imag], axis=1)


def cost_map(
    problem: RingdownProblem, q: NDArray[np.float64], magnitudes_rad: ArrayLike, offsets_rad: ArrayLike
) -> NDArray[np.float64]:
    """The variable-projection cost Σ_c w_c²·‖r_c‖² at (θmax, ε) on the grid, f, δ and φ from
    ``q``, for θmax = −magnitudes (reversed) then +magnitudes (θmax < 0 is the same swing half
    a period later): (2M, E). Where the best κ of a channel would be negative, that channel's
    κ is 0."""
    columns = _shape_columns(problem, q, np.asarray(magnitudes_rad, float))
    n = columns.shape[2]
    y = problem.y - problem.y.mean(axis=1, keepdims=True)
    means = columns.mean(axis=2)
    # The centred Gram matrix (B_DC is free); y is centred, so its products need no centring.
    gram = columns @ columns.transpose(0, 2, 1) - n * means[:, :, None] * means[:, None, :]
    products = y @ columns.transpose(0, 2, 1)
    # x → −x keeps cos(kx) and turns sin(kx) over: the negative θmax from the same sums.
    flip = np.concatenate([np.ones(columns.shape[1] // 2), -np.ones(columns.shape[1] // 2)])
    gram = np.concatenate([(gram * np.outer(flip, flip))[::-1], gram])
    products = np.concatenate([(products * flip)[::-1], products])
    weights = _weights(problem.pickups[0], offsets_rad)
    norm2 = np.sum((weights @ gram) * weights, axis=2)
    projection = products @ weights.T
    explained = np.where(projection > 0, projection**2 / np.maximum(norm2, 1e-300)[:, None, :], 0.0)
    w2 = problem.weights**2
    return float(w2 @ np.sum(y**2, axis=1)) - np.einsum("c,ace->ae", w2, explained)


def offset_starts(
    problem: RingdownProblem, q: NDArray[np.float64], bound_rad: float, amplitude_bound_rad: float, count: int = 3
) -> list[NDArray[np.float64]]:
    """Starting points (f, δ, θmax, φ, ε) at the ``count`` lowest distinct minima of the cost
    over ε ∈ [−bound, bound] (each at its best θmax ∈ [−bound, bound] on the grid), lowest
    first. f, δ and φ come from ``q``."""
    offsets = np.arange(-bound_rad, bound_rad + OFFSET_STEP_RAD / 2, OFFSET_STEP_RAD)
    magnitudes = np.arange(AMPLITUDE_STEP_RAD, amplitude_bound_rad + AMPLITUDE_STEP_RAD / 2, AMPLITUDE_STEP_RAD)
    amplitudes = np.concatenate([-magnitudes[::-1], magnitudes])
    costs = cost_map(problem, q, magnitudes, offsets)
    best = costs.argmin(axis=0)
    profile = costs[best, np.arange(offsets.size)]
    padded = np.concatenate([[np.inf], profile, [np.inf]])
    minima = np.flatnonzero((profile <= padded[:-2]) & (profile <= padded[2:]))
    chosen = minima[np.argsort(profile[minima])][:count]
    return [np.array([q[0], q[1], amplitudes[best[e]], q[3], offsets[e]]) for e in chosen]
