"""Which amplitude a ring-down's frequency belongs to: the averaging of a constant-frequency fit.

The probe is not a linear oscillator: its frequency depends on the amplitude A (harmonic
balance, :meth:`mows.physics.potential.ArcPotential.frequency_hz`). During one ring-down the
amplitude decays, A(t) = A0·e^(−δt), so the instantaneous frequency f(A(t)) drifts, while the
estimator (:func:`mows.estimate.ringdown.fit_ringdown`) fits one constant f. What does it report?

Derivation. Write the signal of Eq. S11 as S = κ·g(θ0 + x) with x = A·cos Φ and
g(θ) = 2a·cos θ − b·sin θ (sensor direction (a, b); the paper's is (0, 1)). A phase error ε
changes S by −κ·g'(θ0 + x)·A·sin Φ·ε. Over whole cycles this is orthogonal to the changes
caused by κ, the offset, A and δ (their products with it are odd in Φ), so the least-squares
fit of (f, φ) is a weighted linear regression of the phase on time, with weights

    w(t) = A(t)²·⟨g'(θ0 + A(t)·cos Φ)²·sin²Φ⟩_Φ

(∝ A² at θ0 = 0°, ∝ A⁴ at 90° where the signal is at 2f). The regression slope of the phase
Φ(t) = ∫ 2π f(t') dt' is, after integrating by parts, an average of the instantaneous frequency

    f_fit = ∫ K(t)·f(A(t)) dt,  K(t) = ∫_t^T w(s)·(s − t̄) ds / ∫_0^T w(s)·(s − t̄)² ds,

with t̄ = ∫ w·s / ∫ w. K ≥ 0 and ∫ K = 1: the lever (s − t̄) of the frequency regression
times the weight. :func:`amplitude_nodes` turns K into a Gauss quadrature of a few amplitude
nodes, so that f_fit = Σ_q c_q·f(A_q) costs a few harmonic-balance evaluations. The
derivation is checked against the estimator itself on chirped ring-downs (tests/lab).

The ring-down's start amplitude is the swing about the rest angle at the first fitted sample
(:func:`swing_from_stop_rad`; the CSV column ``amplitude_deg``); by default the fit window is
the paper's 60 periods.

A swing measured from the signal's size through a pickup about the undeflected lever (θ = 0,
as a fit that does not know the rest angle has it) is not the swing about the rest angle θs:
the magnet swings about θs, where the pickup's slope g'(θs) differs from g'(0) by a few percent
per 10 mrad wherever its second harmonic is strong. :func:`swing_about_rest_rad` converts it:
the swing about θs whose signal has the same variance over the window.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from mows.physics.fluxgate import paper_pickup
from mows.physics.schema import Vector


def swing_from_stop_rad(
    stop_rad: ArrayLike,
    rest_angle_rad: ArrayLike,
    damping_per_s: ArrayLike = 0.0,
    since_release_s: ArrayLike = 0.0,
) -> np.ndarray:
    """The swing a ring-down has about its rest angle ``since_release_s`` after its release (the
    switch-off; its fit's first sample is ``start_offset_s`` after it): every ring-down is
    released at the housing stop ``stop_rad`` (measured from the lever's undeflected position),
    so it starts swinging stop − |θs − θ0| about the rest angle θs (``rest_angle_rad`` =
    θs − θ0), and the swing decays as e^(−δ·t) (Eq. S2). NaN where the stop lies inside the
    deflection: no free swing."""
    swing = np.asarray(stop_rad, float) - np.abs(np.asarray(rest_angle_rad, float))
    decayed = swing * np.exp(-np.asarray(damping_per_s, float) * np.asarray(since_release_s, float))
    return np.where(swing > 0, decayed, np.nan)


def stop_from_swing_rad(
    swing_rad: ArrayLike,
    rest_angle_rad: ArrayLike,
    damping_per_s: ArrayLike = 0.0,
    since_release_s: ArrayLike = 0.0,
) -> np.ndarray:
    """The housing stop a ring-down was released at, from its swing about the rest angle
    ``since_release_s`` after the release: :func:`swing_from_stop_rad` inverted, θmax·e^(δ·t) + |θs − θ0|."""
    grown = np.asarray(swing_rad, float) * np.exp(np.asarray(damping_per_s, float) * np.asarray(since_release_s, float))
    return grown + np.abs(np.asarray(rest_angle_rad, float))


MAD_TO_SD = 1.4826  # the median absolute deviation of a normal sample is 0.6745 sd
MEDIAN_EFFICIENCY = 1.2533  # √(π/2): the median's standard error over the mean's, normal samples
MIN_STOP_FITS = 5  # a spread from fewer ring-downs is no standard error


def stop_median_std_rad(stops_rad: ArrayLike) -> float:
    """The standard error of the median of the stops the ring-downs give
    (:func:`stop_from_swing_rad`, the finite ones): √(π/2)·sd/√n with sd from their median
    absolute deviation; NaN from fewer than MIN_STOP_FITS."""
    stops = np.asarray(stops_rad, float)
    stops = stops[np.isfinite(stops)]
    if stops.size < MIN_STOP_FITS:
        return float("nan")
    spread = MAD_TO_SD * float(np.median(np.abs(stops - np.median(stops))))
    return MEDIAN_EFFICIENCY * spread / float(np.sqrt(stops.size))


DEFAULT_PERIODS = 60.0  # the paper evaluates 60 periods per ring-down
GRID_POINTS = 128  # midpoint grid over the ring-down for K(t)
PHASE_POINTS = 16  # samples of the cycle average ⟨…⟩_Φ (exact for the low harmonics involved)
DEFAULT_NODES = 3  # Gauss nodes: exact for f(A(t)) polynomial of degree 5 in t
PAPER_SENSOR = (0.0, 1.0)


def phase_weight(
    theta0_rad: ArrayLike,
    amplitude_rad: ArrayLike,
    sensor_direction: Vector = PAPER_SENSOR,
    pickup: ArrayLike | None = None,
) -> np.ndarray:
    """w = A²·⟨S'(A·cos Φ)²·sin²Φ⟩_Φ, the phase information per unit time (arbitrary units).

    S(x) = Σ_k Re(C_k·e^(ikx)) is the signal as a function of the deflection x: ``pickup``, the
    C_k the ring-down was fitted with (:func:`mows.physics.fluxgate.pickup_harmonics`, shape
    ``amplitude_rad.shape + (K + 1,)`` or broadcasting to it), or, when None, Eq. S11 with
    ``sensor_direction``: C_1 = (2a + ib)·e^(iθ0), so that S' = g'(θ0 + x). The magnet's
    swing on its lever gives the exact pickup harmonics beyond the first: at θ0 = 90°, where
    the far-field signal is even in x, they carry a first harmonic of the swing that the
    far-field weight leaves out. ``theta0_rad`` and ``amplitude_rad`` broadcast.
    """
    amplitude = np.asarray(amplitude_rad, float)
    if pickup is None:
        pickup = paper_pickup(theta0_rad, sensor_direction)
    coefficients = np.asarray(pickup, complex)
    derivative = 1j * np.arange(coefficients.shape[-1]) * coefficients  # ik·C_k
    # Half a cycle suffices: Φ and 2π − Φ share cos Φ and sin²Φ.
    half = PHASE_POINTS // 2
    phi = np.pi * (np.arange(half) + 0.5) / half
    swing = np.exp(1j * amplitude[..., None] * np.cos(phi))  # e^(ix), (..., Φ)
    # S'(x) = Re Σ_k ik·C_k·e^(ikx): Horner's rule in e^(ix), one exponential instead of K + 1.
    slope = derivative[..., -1:]
    for k in range(derivative.shape[-1] - 2, -1, -1):
        slope = slope * swing + derivative[..., k : k + 1]
    return (amplitude[..., None] ** 2 * (slope.real * np.sin(phi)) ** 2).mean(-1)


def averaging_kernel(
    theta0_rad: ArrayLike,
    amplitude_start_rad: ArrayLike,
    damping_per_s: ArrayLike,
    duration_s: ArrayLike,
    sensor_direction: Vector = PAPER_SENSOR,
    pickup: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Times t (n, M) over the fit window and the kernel masses K(t)·dt (n, M), summing to 1.

    Arguments broadcast to a batch shape (n,); ``pickup`` (n, K + 1) or (K + 1,) as in
    :func:`phase_weight`. See the module docstring for K.

    NaN masses where the weight vanishes over the whole window, so that nothing fixes the
    phase and there is no fit to average: a start swing of 0, which is what a sweep's model
    gives where the housing stop lies inside the rest deflection (the field holds the lever on
    its stop and nothing rings: :meth:`mows.physics.potential.ArcPotential.start_swing_rad`),
    a pickup that is zero, or a window of no length. The small-swing kernel, the limit A0 → 0,
    exists but belongs to a ring-down that rings, however little; a lever on its stop has none.
    """
    theta0, amp0, damping, duration = np.broadcast_arrays(
        *(np.atleast_1d(np.asarray(v, float)) for v in (theta0_rad, amplitude_start_rad, damping_per_s, duration_s))
    )
    step = duration / GRID_POINTS
    t = (np.arange(GRID_POINTS) + 0.5) * step[:, None]
    per_point = None if pickup is None else np.atleast_2d(np.asarray(pickup, complex))[:, None, :]
    weight = phase_weight(theta0[:, None], amp0[:, None] * np.exp(-damping[:, None] * t), sensor_direction, per_point)
    centre = _ratio((weight * t).sum(-1, keepdims=True), weight.sum(-1, keepdims=True))
    lever = weight * (t - centre)
    # ∫_t^T w·(s − t̄) ds on the grid: everything after the cell plus half of the cell itself.
    tail = np.cumsum(lever[:, ::-1], axis=-1)[:, ::-1] - 0.5 * lever
    mass = np.clip(tail, 0.0, None)
    return t, _ratio(mass, mass.sum(-1, keepdims=True))


def _ratio(numerator: np.ndarray, denominator: np.ndarray) -> np.ndarray:
    """numerator / denominator, NaN where the denominator is not positive: no phase information
    anywhere in the window, so no kernel (:func:`averaging_kernel`)."""
    shape = np.broadcast(numerator, denominator).shape
    return np.divide(numerator, denominator, out=np.full(shape, np.nan), where=denominator > 0)


def amplitude_nodes(
    theta0_rad: ArrayLike,
    amplitude_start_rad: ArrayLike,
    damping_per_s: ArrayLike,
    duration_s: ArrayLike,
    nodes: int = DEFAULT_NODES,
    sensor_direction: Vector = PAPER_SENSOR,
    pickup: ArrayLike | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Amplitudes A_q (n, q) and weights c_q (n, q) with f_fit = Σ_q c_q·f(A_q).

    Gauss quadrature for the measure K(t)·dt (Stieltjes recurrence on the grid, then the
    eigen-decomposition of the Jacobi matrix), mapped to amplitudes by A = A0·e^(−δt).
    """
    t, mass = averaging_kernel(theta0_rad, amplitude_start_rad, damping_per_s, duration_s, sensor_direction, pickup)
    span = t[:, -1:] + t[:, :1]
    x = 2.0 * t / span - 1.0  # the window mapped to [−1, 1] for conditioning
    alpha, beta = [], []
    previous, current = np.zeros_like(x), np.ones_like(x)
    norm_previous = np.ones(len(x))
    for k in range(nodes):
        norm = (mass * current**2).sum(-1)
        alpha.append((mass * x * current**2).sum(-1) / norm)
        beta.append(norm / norm_previous if k else np.zeros(len(x)))
        previous, current = current, (x - alpha[-1][:, None]) * current - (beta[-1][:, None] * previous if k else 0.0)
        norm_previous = norm
    jacobi = np.zeros((len(x), nodes, nodes))
    idx = np.arange(nodes)
    jacobi[:, idx, idx] = np.stack(alpha, -1)
    off = np.sqrt(np.stack(beta[1:], -1)) if nodes > 1 else np.zeros((len(x), 0))
    jacobi[:, idx[:-1], idx[1:]] = off
    jacobi[:, idx[1:], idx[:-1]] = off
    bad = ~np.all(np.isfinite(jacobi), axis=(1, 2))  # no kernel (NaN inputs, no swing): NaN nodes, not an error
    eigenvalues, vectors = np.linalg.eigh(np.where(bad[:, None, None], 0.0, jacobi))
    eigenvalues[bad] = np.nan
    times = (eigenvalues + 1.0) * span / 2.0
    damping = np.broadcast_to(np.atleast_1d(np.asarray(damping_per_s, float)), (len(x),))
    amp0 = np.broadcast_to(np.atleast_1d(np.asarray(amplitude_start_rad, float)), (len(x),))
    return amp0[:, None] * np.exp(-damping[:, None] * times), np.where(bad[:, None], np.nan, vectors[:, 0, :] ** 2)


SWING_ITERATIONS = 12  # the fixed point A ← A·√(v/v(A)) gains ~2 digits a step (v ∝ A² to first order)
SWING_TOLERANCE = 1e-13  # relative step below which the fixed point has converged to rounding


def pickup_variance(
    swing_rad: ArrayLike, pickup: ArrayLike, damping_per_s: ArrayLike, duration_s: ArrayLike, rest_rad: ArrayLike
) -> np.ndarray:
    """Variance over the window and the cycle of g(θs + A0·e^(−δt)·cos Φ), g(x) = Re Σ_k C_k·e^(ikx):
    the signal's size per unit pickup scale of a swing A0 about the rest angle θs. The window is
    many periods, so Φ runs uniformly over the cycle at every t. ``pickup`` (…, K + 1); the
    others broadcast over its leading axes."""
    coefficients = np.asarray(pickup, complex)
    fraction = (np.arange(GRID_POINTS) + 0.5) / GRID_POINTS
    decay = np.exp(-np.multiply.outer(np.asarray(damping_per_s, float) * np.asarray(duration_s, float), fraction))
    # cos Φ at the cycle's midpoints: those of the second half repeat the first's, as often
    phase = np.cos(2.0 * np.pi * (np.arange(PHASE_POINTS // 2) + 0.5) / PHASE_POINTS)
    angle = np.asarray(rest_rad, float)[..., None, None] + np.asarray(swing_rad, float)[..., None, None] * (
        decay[..., :, None] * phase
    )
    # Σ_k C_k·z^k by Horner's rule in z = e^(iθ): one complex exponential per sample, not K + 1
    z = np.exp(1j * angle)
    signal = np.broadcast_to(coefficients[..., -1, None, None], z.shape)
    for k in range(coefficients.shape[-1] - 2, -1, -1):
        signal = signal * z + coefficients[..., k, None, None]
    return signal.real.var(axis=(-2, -1))


def swing_about_rest_rad(
    swing_rad: ArrayLike,
    pickup: ArrayLike,
    damping_per_s: ArrayLike,
    duration_s: ArrayLike,
    rest_rad: ArrayLike,
) -> np.ndarray:
    """The swing about the rest angle θs whose signal through ``pickup`` has the variance that a
    swing ``swing_rad`` about the undeflected lever (θ = 0) has (module docstring): the signal's
    size is what was measured, θs is what the swing is about. Arguments broadcast as in
    :func:`pickup_variance`; NaN where the swing or the pickup gives no signal."""
    coefficients = np.asarray(pickup, complex)
    shape = np.broadcast_shapes(
        np.shape(swing_rad), coefficients.shape[:-1], np.shape(damping_per_s), np.shape(duration_s), np.shape(rest_rad)
    )
    swing0, damping, duration, rest = (
        np.broadcast_to(np.asarray(a, float), shape) for a in (swing_rad, damping_per_s, duration_s, rest_rad)
    )
    coefficients = np.broadcast_to(coefficients, (*shape, coefficients.shape[-1]))
    target = pickup_variance(swing0, coefficients, damping, duration, 0.0)
    swing = swing0.copy()
    # Each element iterates until its own step converges, whatever else is asked with it: a
    # swing is the same alone as in a table.
    todo = np.ones(shape, bool)
    for _ in range(SWING_ITERATIONS):
        at = todo.copy()
        variance = pickup_variance(swing[at], coefficients[at], damping[at], duration[at], rest[at])
        step = np.sqrt(np.divide(target[at], variance, out=np.full(variance.shape, np.nan), where=variance > 0))
        swing[at] = swing[at] * step
        todo[at] = np.abs(step - 1.0) > SWING_TOLERANCE  # NaN (no signal) stays NaN, converged
        if not todo.any():
            break
    return swing


def default_duration_s(f_hz: ArrayLike) -> np.ndarray:
    """The paper's fit window, 60 periods, s."""
    return DEFAULT_PERIODS / np.asarray(f_hz, float)
