"""The harmonic balance of a swing in a potential held as a Chebyshev series, row by row.

The kernels behind :class:`mows.physics.potential.ArcPotential`'s rest angle, cycle centre and
effective stiffness k(A): for each row of U' and U'' coefficients (a Chebyshev series in θ/w on
[−w, w]) and its spring kM, the cycle's balance in its mean, cos φ and cos 2φ parts (the physics is
in :mod:`mows.physics.potential`'s docstring), solved by Newton's method, compiled with numba.
"""

import math

import numpy as np
from numba import njit

BALANCE_POINTS = 48
HALF_CYCLE = BALANCE_POINTS // 2 + 1  # phases 0 … π: the swing is even in φ, so they hold the whole cycle
NEWTON_STEPS = 30


# --- the balances, row by row (compiled) -----------------------------------------------------
# The lab solves these for small batches thousands of times per analysis; written as numpy
# over the batch, the Newton loops spent their time in per-operation overhead. Each row now
# iterates until it has converged itself.
@njit(cache=True)
def _series(coeffs: np.ndarray, x: float) -> float:
    """Σ c_j T_j(x) (Clenshaw) for one row's coefficients."""
    b1, b2 = 0.0, 0.0
    for j in range(coeffs.shape[0] - 1, 0, -1):
        b1, b2 = 2.0 * x * b1 - b2 + coeffs[j], b1
    return x * b1 - b2 + coeffs[0]


@njit(cache=True)
def _centre_row(d1: np.ndarray, d2: np.ndarray, spring: float, amplitude: float, half_width: float) -> float:
    """θc of ⟨U'(θc + A·cos φ)⟩ = 0 for one row
    (:meth:`mows.physics.potential.ArcPotential.cycle_centre_rad`)."""
    points = HALF_CYCLE if amplitude != 0.0 else 1  # at rest the balance is U'(θc) = 0 itself
    centre, step = 0.0, np.inf
    for _ in range(NEWTON_STEPS):
        slope, curvature = 0.0, 0.0
        for i in range(points):
            theta = centre + amplitude * math.cos(2.0 * math.pi * i / BALANCE_POINTS)
            weight = _cycle_weight(i, points)
            slope += weight * (spring * theta + _series(d1, theta / half_width))
            curvature += weight * (spring + _series(d2, theta / half_width))
        step = slope / curvature
        centre = min(max(centre - step, -half_width), half_width)
        if abs(step) < 1e-15 + 1e-12 * abs(centre):
            break
    curvature = 0.0
    for i in range(points):
        theta = centre + amplitude * math.cos(2.0 * math.pi * i / BALANCE_POINTS)
        curvature += _cycle_weight(i, points) * (spring + _series(d2, theta / half_width))
    if curvature > 0.0 and abs(step) < 1e-9 and abs(centre) + amplitude < half_width:
        return centre
    return np.nan


@njit(cache=True)
def _cycle_weight(i: int, points: int) -> float:
    """Weight of phase φ_i = 2πi/BALANCE_POINTS in a mean over the cycle taken on its first half
    (i = 0 … BALANCE_POINTS/2): θ(φ) is even in φ, so φ_i and 2π − φ_i count alike."""
    if points == 1:
        return 1.0
    return (1.0 if i == 0 or i == points - 1 else 2.0) / BALANCE_POINTS


@njit(cache=True)
def centre_rows(
    d1: np.ndarray, d2: np.ndarray, spring: np.ndarray, amplitude: np.ndarray, half_width: float
) -> np.ndarray:
    out = np.empty(amplitude.shape[0])
    for r in range(amplitude.shape[0]):
        out[r] = _centre_row(d1[r], d2[r], spring[r], amplitude[r], half_width)
    return out


@njit(cache=True)
def _series_at(coeffs: np.ndarray, x: np.ndarray, out: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> None:
    """``out[i]`` = Σ c_j T_j(x[i]) by :func:`_series`'s arithmetic, with the points innermost:
    their recurrences are independent, so they run side by side in vector registers instead of
    one latency-bound chain after another. Top coefficients that are exactly 0 (a derivative's
    last) leave the recurrence at 0 and are skipped. ``b1``, ``b2``: work arrays like ``x``."""
    top = coeffs.shape[0]
    while top > 1 and coeffs[top - 1] == 0.0:
        top -= 1
    b1[:] = 0.0
    b2[:] = 0.0
    for j in range(top - 1, 0, -1):
        c = coeffs[j]
        for i in range(x.shape[0]):
            t = 2.0 * x[i] * b1[i] - b2[i] + c
            b2[i] = b1[i]
            b1[i] = t
    for i in range(x.shape[0]):
        out[i] = x[i] * b1[i] - b2[i] + coeffs[0]


@njit(cache=True)
def balance_rows(
    d1: np.ndarray, d2: np.ndarray, spring: np.ndarray, rest: np.ndarray, amplitude: np.ndarray, half_width: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(k(A), θc, A2) per row and amplitude (``amplitude``: (rows, q)): Newton on (θc, A2) with
    the Jacobian's diagonal (its other terms are O(A) smaller) from the row's ``rest`` angle
    (:meth:`mows.physics.potential.ArcPotential._balance`)."""
    rows, nodes = amplitude.shape
    stiffness = np.full((rows, nodes), np.nan)
    mean_out, second_out = np.full((rows, nodes), np.nan), np.full((rows, nodes), np.nan)
    phase = 2.0 * np.pi * np.arange(HALF_CYCLE) / BALANCE_POINTS
    first, second_wave = np.cos(phase), np.cos(2.0 * phase)
    weight = np.array([_cycle_weight(i, HALF_CYCLE) for i in range(HALF_CYCLE)])
    theta, x, b1, b2 = np.empty(HALF_CYCLE), np.empty(HALF_CYCLE), np.empty(HALF_CYCLE), np.empty(HALF_CYCLE)
    torque, bend = np.empty(HALF_CYCLE), np.empty(HALF_CYCLE)
    for r in range(rows):
        # From the rest angle: the cycle's own balance moves the centre by O(A²) from there and
        # converges as fast as from the DC balance's centre, at a fraction of its cost.
        if not np.isfinite(rest[r]):
            continue
        for q in range(nodes):
            a = amplitude[r, q]
            small = a < 1e-9
            divisor = 1.0 if small else a
            mean, second, harmonic, curvature = rest[r], 0.0, 0.0, 0.0
            converged = False
            for _ in range(NEWTON_STEPS):
                for i in range(HALF_CYCLE):
                    theta[i] = mean + a * first[i] + second * second_wave[i]
                    x[i] = theta[i] / half_width
                _series_at(d1[r], x, torque, b1, b2)
                _series_at(d2[r], x, bend, b1, b2)
                slope_mean, slope_first, slope_second, curvature = 0.0, 0.0, 0.0, 0.0
                for i in range(HALF_CYCLE):
                    slope = weight[i] * (spring[r] * theta[i] + torque[i])
                    slope_mean += slope
                    slope_first += slope * first[i]
                    slope_second += slope * second_wave[i]
                    curvature += weight[i] * (spring[r] + bend[i])
                harmonic = 2.0 * slope_first / divisor
                mean_step = slope_mean / curvature
                second_step = (2.0 * slope_second - 4.0 * harmonic * second) / (curvature - 4.0 * harmonic)
                mean, second = mean - mean_step, second - second_step
                if not abs(mean_step) + abs(second_step) >= 1e-15 + 1e-12 * a:
                    converged = True
                    break
            if converged and curvature > 0.0 and abs(mean) + a + abs(second) < half_width:
                stiffness[r, q] = spring[r] + _series(d2[r], rest[r] / half_width) if small else harmonic
                mean_out[r, q], second_out[r, q] = mean, second
    return stiffness, mean_out, second_out
