"""The fit of one free ring-down, Eqs. S2, S11, S12, at the Cramér–Rao bound.

Its options and result types are :mod:`mows.estimate.ringdown.types` (imported here too).

Model of one channel:

    S(t) = κ·g(ε + x(t)) + B_DC,   x(t) = θmax·e^(−δt)·cos(2πft + φ)   (Eq. S2, t = 0 at the
    first fitted sample),   g(x) = Σ_k Re(C_k·e^(ikx)).

ε is the rest-angle offset θs − θ0 (``FitOptions.rest_offset_free``, on by default): a field across
the probe, gravity in the plane or a gradient deflects the rest angle, and the probe swings about
θs, not θ0. Without ε, κ and θmax trade off against it (θmax 3.5°–74° for a true 11°–21° in a
strong perpendicular field); f is nearly orthogonal to it (the bound grows by < 1 %, the fit's
time by 0–12 %).

g is the sensor's signal as a function of the deflection, normalised by κ. The paper's model
(Eq. S11, a sensor along (a, b) and a magnet turning in place) is the single term
C_1 = (2a + ib)·e^(iθ0), i.e. g = 2a·cos(θ0 + x) − b·sin(θ0 + x); its sensors have
(a, b) = (0, 1), which is Eq. S12. On a real lever the magnet also moves, and the exact
pickup (:func:`mows.physics.fluxgate.pickup_harmonics`) adds harmonics of relative size ~(3l/r)^k
(0.11 for k = 2 in the paper's set-up): pass them as ``FitOptions.pickup``. θ0 is taken from
the excitation state (the commanded orientation), or, in the paper's model, fitted.

Estimator. Least squares is the maximum-likelihood estimator for white Gaussian noise, and
reaches the Cramér–Rao bound (docs/physics.md §11) once the fit is converged at full rate. The
fit runs in three stages so that this costs 1–2 ms (0.5 s at 20 kS/s):

1. a start from the zero-padded spectrum: the peaks at f and 2f (near 90° the signal is
   mostly at 2f), the phase of the complex demodulate, and the envelope decay for δ;
2. Levenberg–Marquardt on every D-th sample. Subsampling keeps white noise white and the
   model's harmonics below the new Nyquist frequency, so this stage lands within a few
   standard deviations of the optimum at 1/D of the cost. In a strong field the cost over
   (θmax, ε) has several minima (near θ0 = 90° the signal is nearly even in the deflection,
   and κ trades off against θmax): this stage is also started from every minimum of a grid
   search over the whole range (:mod:`mows.estimate.ringdown.offset`), and from the best
   one's mirror images, with κ > 0. The search (2–3 ms, more than the rest of the fit) runs
   only where the data can pin θmax or ε: where the local optimum's σ of both, scaled to the
   full rate, exceeds the reporting limit below, the fit goes on from the local optimum and
   reports both as not determined (another minimum might pin one; not reporting a number is
   always allowed, a wrong one never). Should the full-rate fit pin one after all, the search
   runs then;
3. Gauss–Newton steps on all samples until the step is < 1e-3 σ in every parameter. The
   Jacobian of the last step gives the covariance and the Fisher information.

What the data do not determine is not reported. θmax and ε are NaN, named in
``RingdownFit.undetermined`` and the reason in its message, where another minimum that differs
by more than half their tolerance (``FitOptions``: 1° and 0.5°) fits within Δχ² = 25, or where
their σ exceeds a third of it. In fields up to 5 mT and gradients up to 50 mT/m the reported
ones are within the tolerance (tests/estimator/test_ringdown_rest_offset.py); a 0.25–0.5 s
ring-down there determines ε in a few percent of the fits and θmax (σ ≥ 0.35°) in none.

Uncertainties. ``frequency_std_hz`` comes from the covariance (JᵀJ)⁻¹·s² with the residual
variance s² (where a diagonal entry of that inverse comes out below zero, rounding in a
numerically singular matrix, the parameter's row and column are NaN and it is named not
determined); ``frequency_crb_hz`` from the Fisher information with the white-noise level
measured independently of the model (from the third difference of the data). If the model
misses something, s exceeds the noise level: χ²/dof > 1 and std > CRB.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable
from typing import Any, SupportsFloat

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mows.estimate.ringdown.offset import offset_starts
from mows.estimate.ringdown.problem import (
    AMPLITUDE,
    NONLINEAR,
    RingdownProblem,
    Step,
    evaluate,
    fisher_information,
    scaled_inverse,
    variable_projection,
)
from mows.estimate.ringdown.start import start_candidates, white_noise_std
from mows.estimate.ringdown.types import FitOptions, FitStatus, RingdownFit, failure, parameter_std

TWO_PI = 2.0 * math.pi
# Another minimum of the cost closer than this (Δχ², in units of χ²/dof) is a rival: noise
# reverses the order of two minima 25 apart less than once in 150 (Δχ²'s σ is 2·√Δχ²).
RIVAL_CHI2 = 25.0
# A number is reported where its tolerance is this many σ: beyond it lies 1 fit in 370.
DETERMINED_SIGMAS = 3.0
OFFSET = len(NONLINEAR)  # q's index of the rest offset ε (or θ0's error) when it is free


def _parameter_names(n_channels: int, options: FitOptions) -> list[str]:
    offset = ["theta0_rad"] if options.theta0_free else ["rest_offset_rad"] if options.rest_offset_free else []
    names = list(NONLINEAR) + offset
    for c in range(n_channels):
        suffix = "" if n_channels == 1 else f"_{c + 1}"
        names += [f"kappa_t{suffix}", f"offset_t{suffix}"]
    return names


# --- the usable window -----------------------------------------------------------------------
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


# --- the fit ----------------------------------------------------------------------------
def fit_ringdown(
    samples: ArrayLike,
    sample_rate_hz: float,
    theta0_rad: float,
    expected_frequency_hz: float,
    saturated: ArrayLike | None = None,
    options: FitOptions = FitOptions(),
    damping_guess_per_s: float = 1.8,
    coil_off_skip_s: float = 0.0,
) -> RingdownFit:
    """Fit one free ring-down.

    Parameters
    ----------
    samples : (n,) or (n, 2) array, tesla; sample 0 is the instant the coils switched off.
    sample_rate_hz : device sample rate.
    theta0_rad : commanded probe orientation (start value when ``options.theta0_free``).
    expected_frequency_hz : where to look, e.g. the excitation frequency.
    saturated : optional boolean mask like ``samples``.
    coil_off_skip_s : samples before this time are not used (coil current decay, sensor recovery).

    Returns
    -------
    RingdownFit, with a non-OK status and a message (and NaN numbers) when the data cannot
    give an honest frequency. Never raises on bad data.
    """
    known = {"theta0_rad": float(theta0_rad), "theta0_free": options.theta0_free}
    fs = _as_float(sample_rate_hz)
    if not (math.isfinite(fs) and fs > 0):
        return failure(
            FitStatus.BAD_SAMPLE_RATE, f"sample rate {sample_rate_hz!r} Hz is not a positive number", **known
        )
    expected_frequency_hz = _as_float(expected_frequency_hz)
    if not (math.isfinite(expected_frequency_hz) and expected_frequency_hz > 0):
        return failure(
            FitStatus.BAD_SAMPLE_RATE, f"expected frequency {expected_frequency_hz!r} Hz is not positive", **known
        )
    if expected_frequency_hz * (1 + options.search_fraction) * 2 * 3 > fs / 2:
        return failure(
            FitStatus.BAD_SAMPLE_RATE,
            f"sample rate {fs:g} Hz cannot resolve a ring-down near {expected_frequency_hz:g} Hz "
            f"and its harmonics (needs > {12 * expected_frequency_hz * (1 + options.search_fraction):.0f}"
            " Hz)",
            **known,
        )
    data = np.asarray(samples, float)
    if data.ndim not in (1, 2) or data.shape[0] == 0:
        return failure(FitStatus.TOO_SHORT, f"no samples (shape {data.shape})", **known)
    if not np.all(np.isfinite(data)):
        bad = int(np.count_nonzero(~np.isfinite(data)))
        return failure(FitStatus.INVALID_SAMPLES, f"{bad} NaN or infinite samples in the ring-down", **known)
    mask = np.zeros(data.shape, bool) if saturated is None else np.asarray(saturated, bool)
    start, stop = usable_window(mask, int(round(coil_off_skip_s * fs)))
    min_samples = int(math.ceil(options.min_periods * fs / expected_frequency_hz))
    if stop - start < min_samples:
        why = FitStatus.SATURATED if mask.any() else FitStatus.TOO_SHORT
        return failure(
            why,
            f"{stop - start} usable samples ({(stop - start) / fs * 1e3:.1f} ms) after removing "
            f"{int(mask.reshape(len(mask), -1).any(axis=1).sum())} saturated samples; "
            f"need {min_samples} ({options.min_periods:g} periods)",
            **known,
        )
    y = combine_channels(data[start:stop], options.channels)
    return _fit_window(
        y, fs, float(theta0_rad), float(expected_frequency_hz), options, damping_guess_per_s, start / fs, known
    )


def _problem(y: NDArray[np.float64], fs: float, theta0: float, options: FitOptions) -> RingdownProblem:
    noise = np.array([white_noise_std(ch) for ch in y])
    if np.any(noise <= 0):  # noiseless, or quantised to a constant: weight channels equally
        noise = np.full(y.shape[0], max(float(np.ptp(y)) * 1e-9, 1e-30))
    return RingdownProblem(
        np.ascontiguousarray(y, float), 1.0 / noise, 1.0 / fs, theta0, options.pickup_at(theta0), options.offset_free
    )


def _coarse_start(
    problem: RingdownProblem, fs: float, expected_hz: float, options: FitOptions, damping_guess: float
) -> tuple[RingdownProblem, NDArray[np.float64] | None]:
    """The subsampled problem and the best spectral start on it, or (coarse, None)."""
    coarse = problem.subsampled(max(1, int(fs // (16.0 * expected_hz))))
    starts = start_candidates(coarse.y.sum(axis=0), 1.0 / coarse.dt, expected_hz, options, damping_guess)
    if not starts:
        return coarse, None
    extra = [0.0] if options.offset_free else []  # the rest offset (or θ0's error) starts at 0
    return coarse, min((np.concatenate([s_, extra]) for s_ in starts), key=lambda q: evaluate(coarse, q, False).cost)


def starting_point(
    samples: ArrayLike,
    sample_rate_hz: float,
    theta0_rad: float,
    expected_frequency_hz: float,
    options: FitOptions = FitOptions(),
    damping_guess_per_s: float = 1.8,
) -> NDArray[np.float64] | None:
    """The point the fit starts from: (f, δ, θmax, φ, [ε,] κ, B_DC) of the first channel, from
    the spectral stage, or None if no line is found (ε: the rest offset, or θ0's error, when
    ``options`` fit one). For comparisons with other optimisers."""
    y = combine_channels(samples, options.channels)
    problem = _problem(y, float(sample_rate_hz), float(theta0_rad), options)
    _, q0 = _coarse_start(problem, float(sample_rate_hz), float(expected_frequency_hz), options, damping_guess_per_s)
    return None if q0 is None else np.concatenate([q0, evaluate(problem, q0, False).coef[0]])


def wrapped_rad(angle_rad: float) -> float:
    """The angle in (−π, π]."""
    return float(-((math.pi - angle_rad) % TWO_PI - math.pi)) + 0.0  # + 0.0: no −0.0


def _as_float(value: SupportsFloat | str) -> float:
    """A number from a parameter that may be missing or malformed; NaN when it is not one."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _fit_window(
    y: NDArray[np.float64],
    fs: float,
    theta0: float,
    expected_hz: float,
    options: FitOptions,
    damping_guess: float,
    start_s: float,
    known: dict[str, Any],
) -> RingdownFit:
    problem = _problem(y, fs, theta0, options)
    coarse, q0 = _coarse_start(problem, fs, expected_hz, options, damping_guess)
    if q0 is None:
        return failure(
            FitStatus.NO_OSCILLATION,
            f"no spectral line near {expected_hz:.2f} Hz or its double "
            f"stands above the noise floor (×{options.detection_snr:g})",
            **known,
        )
    step, _, _, _ = variable_projection(coarse, q0, options.max_iterations, tol_chi2=1e-2)
    fit: RingdownFit | None = None
    searched = options.rest_offset_free and not options.theta0_free
    if searched and not _pinned_locally(step, coarse, problem, options):
        # Neither θmax nor ε has σ within its reporting limit at the local optimum: the search
        # over (θmax, ε) could only move numbers that are not reported, at twice the fit's cost.
        # Kept only if the full-rate fit agrees (both NaN); else the search runs as below.
        fit = _refined(problem, step.q, [], options, expected_hz, start_s, known)
        if not (fit.ok and math.isnan(fit.amplitude_rad) and math.isnan(fit.rest_offset_rad)):
            fit = None
    if fit is None:
        others: list[Step] = []
        if searched:
            step, *others = _offset_minima(coarse, step, options)
        fit = _refined(problem, step.q, others, options, expected_hz, start_s, known)
    if fit.status == FitStatus.NOT_CONVERGED and options.rest_offset_free and not options.theta0_free:
        # The offset has no handle (near 90° the signal is even in it, at a small θmax it is
        # lost in κ): the swing about θ0, as the paper's model has it, and the reason said.
        fallback = dataclasses.replace(options, rest_offset_free=False)
        fit = _fit_window(y, fs, theta0, expected_hz, fallback, damping_guess, start_s, known)
        if not fit.ok:
            return fit
        # θmax about θ0 is not the swing about a rest angle the data did not give.
        note = "rest offset and θmax not determined: fitted without the offset"
        return dataclasses.replace(
            fit,
            amplitude_rad=math.nan,
            message="; ".join(filter(None, [note, fit.message])),
            undetermined=tuple(dict.fromkeys(("rest_offset_rad", "amplitude_rad", *fit.undetermined))),
        )
    return fit


def _refined(
    problem: RingdownProblem,
    start: NDArray[np.float64],
    others: list[Step],
    options: FitOptions,
    expected_hz: float,
    start_s: float,
    known: dict[str, Any],
) -> RingdownFit:
    """The full-rate fit from a coarse optimum ``start`` (within a few σ of the full-rate one:
    started as Gauss–Newton), summarised, with what ``others`` (rival coarse optima) or the
    σ leave undetermined removed."""
    step, converged, iters, free = variable_projection(problem, start, options.max_iterations, 1e-4, damping=1e-6)
    if not converged:  # a weakly determined θmax or rest offset can crawl: the cautious Marquardt λ
        step, converged, iters, free = variable_projection(problem, start, options.max_iterations, 1e-4, damping=1e-3)
    if not converged:
        return failure(FitStatus.NOT_CONVERGED, f"the fit did not converge in {iters} iterations", **known)
    fit = _summarise(step, problem, free, 1.0 / problem.weights, options, expected_hz, start_s, known)
    return _undetermined_removed(fit, problem, step.cost, others, options) if fit.ok else fit


def _pinned_locally(step: Step, coarse: RingdownProblem, problem: RingdownProblem, options: FitOptions) -> bool:
    """Whether θmax or ε could be reported from the coarse optimum ``step``: its σ at the full
    rate (the coarse covariance scaled by the ratio of the sample counts, the noise level as
    the weights have it) within tolerance/DETERMINED_SIGMAS. A numerically singular normal
    matrix pins neither."""
    if step.normal_matrix is None:
        return True
    try:
        covariance = scaled_inverse(step.normal_matrix) * coarse.y.shape[1] / problem.y.shape[1]
    except np.linalg.LinAlgError:
        return False
    limits = {AMPLITUDE: options.amplitude_tolerance_rad, OFFSET: options.rest_offset_tolerance_rad}
    return any(
        covariance[i, i] >= 0 and math.sqrt(covariance[i, i]) <= tolerance / DETERMINED_SIGMAS
        for i, tolerance in limits.items()
    )


def _offset_minima(coarse: RingdownProblem, step: Step, options: FitOptions) -> list[Step]:
    """The distinct coarse optima reached from every minimum of the cost over the rest offset
    (:func:`mows.estimate.ringdown.offset.offset_starts`), from the local ``step`` and from the
    best one's mirror images, lowest cost first. κ < 0 turns g into −g, the same waveform as a
    pickup turned by another offset: such optima are left out unless there is no other."""
    solutions = [step]

    def refine(starts: Iterable[NDArray[np.float64]]) -> None:
        solutions.extend(
            variable_projection(coarse, start, options.max_iterations, tol_chi2=1e-2)[0] for start in starts
        )

    def distinct() -> list[Step]:
        physical = [s for s in solutions if np.all(s.coef[:, 0] > 0)] or solutions
        kept: list[Step] = []
        for solution in sorted(physical, key=lambda s: s.cost):
            if not any(_agree(solution.q, other.q, options) for other in kept):
                kept.append(solution)
        return kept

    refine(offset_starts(coarse, step.q, options.theta_stop_rad, 2.0 * options.theta_stop_rad))
    # The mirror images, closer than the search's grid resolves: near 0° the sign of a small
    # offset is carried by the weak line at 2f, near 90° it goes with the swing's.
    best = distinct()[0].q
    refine(best * np.array([1, 1, sign, 1, -1]) for sign in (1, -1))
    return distinct()


def _offset_apart(q: NDArray[np.float64], other: NDArray[np.float64], options: FitOptions) -> bool:
    return abs(wrapped_rad(q[4] - other[4])) > options.rest_offset_tolerance_rad / 2


def _amplitude_apart(q: NDArray[np.float64], other: NDArray[np.float64], options: FitOptions) -> bool:
    return abs(abs(q[AMPLITUDE]) - abs(other[AMPLITUDE])) > options.amplitude_tolerance_rad / 2


def _agree(q: NDArray[np.float64], other: NDArray[np.float64], options: FitOptions) -> bool:
    return not (_offset_apart(q, other, options) or _amplitude_apart(q, other, options))


def _undetermined_removed(
    fit: RingdownFit, problem: RingdownProblem, cost: float, others: list[Step], options: FitOptions
) -> RingdownFit:
    """``fit`` with θmax and the rest offset NaN, the reason said, where the data do not pin
    them within ``options``' tolerances: another minimum of the cost (``others``, coarse
    optima) fits within Δχ² = RIVAL_CHI2 (in units of the fit's χ²/dof) and differs by more
    than half the tolerance, or the tolerance is less than DETERMINED_SIGMAS of the parameter's σ."""
    q = np.array([fit.frequency_hz, fit.damping_per_s, fit.amplitude_rad, fit.phase_rad, fit.rest_offset_rad])
    rivals = [o.q for o in others if evaluate(problem, o.q, False).cost - cost < RIVAL_CHI2 * fit.chi2_dof]
    changes: dict[str, Any] = {}
    reasons: list[str] = []
    if not math.isfinite(fit.amplitude_rad) and math.isfinite(fit.rest_offset_rad):
        # θmax at its bound, κ unbounded: the offset then only sets the ratio of the lines at f and 2f.
        changes["rest_offset_rad"] = math.nan
        reasons.append("rest offset not determined where θmax is not")
    for name, tolerance, apart in (
        ("amplitude_rad", options.amplitude_tolerance_rad, _amplitude_apart),
        ("rest_offset_rad", options.rest_offset_tolerance_rad, _offset_apart),
    ):
        value, std = getattr(fit, name), parameter_std(fit.parameter_names, fit.covariance, name)
        if not math.isfinite(value) or name in changes:
            continue
        rival = next((r for r in rivals if apart(q, r, options)), None)
        what = "θmax" if name == "amplitude_rad" else "rest offset"
        if rival is not None:
            other = abs(rival[AMPLITUDE]) if name == "amplitude_rad" else wrapped_rad(rival[4])
            reasons.append(
                f"{what} not determined: {math.degrees(value):.1f}° and {math.degrees(other):.1f}° fit "
                f"within Δχ² < {RIVAL_CHI2:g}"
            )
        elif not std <= tolerance / DETERMINED_SIGMAS:
            limit = math.degrees(tolerance) / DETERMINED_SIGMAS
            reasons.append(f"{what} not determined: σ {math.degrees(std):.2f}° > {limit:.2f}°")
        else:
            continue
        changes[name] = math.nan
    if not changes:
        return fit
    return dataclasses.replace(
        fit,
        message="; ".join(filter(None, [fit.message, *reasons])),
        undetermined=fit.undetermined + tuple(changes),
        **changes,
    )


def _summarise(
    step: Step,
    problem: RingdownProblem,
    free: NDArray[np.bool_],
    noise: NDArray[np.float64],
    options: FitOptions,
    expected_hz: float,
    start_s: float,
    known: dict[str, Any],
) -> RingdownFit:
    q, y = step.q, problem.y
    n_ch, n = y.shape
    if q[0] < options.min_frequency_fraction * expected_hz:
        return failure(
            FitStatus.NEGATIVE_STIFFNESS,
            f"fitted frequency {q[0]:.3f} Hz is below {options.min_frequency_fraction:g} × the expected "
            f"{expected_hz:.2f} Hz: the restoring spring is (nearly) cancelled (k ≤ 0 beyond B = −kM/m)",
            **known,
        )
    fisher = fisher_information(step, problem.weights)
    fitted = np.concatenate([free, np.ones(2 * n_ch, bool)])
    fisher_inv = np.full(fisher.shape, np.nan)
    try:
        fisher_inv[np.ix_(fitted, fitted)] = scaled_inverse(fisher[np.ix_(fitted, fitted)])
    except np.linalg.LinAlgError:
        return failure(FitStatus.NOT_CONVERGED, "singular Fisher information: parameters not identifiable", **known)
    note = (
        ""
        if free[AMPLITUDE]
        else (
            f"θmax not determined (the fit ran to its bound {math.degrees(abs(step.q[AMPLITUDE])):.1f}°): at this "
            "orientation the data do not separate θmax from κ; f is unaffected"
        )
    )
    chi2_dof = step.cost / (step.residual.size - int(fitted.sum()))
    covariance = fisher_inv * chi2_dof
    if not np.all(np.isfinite(covariance[np.ix_(fitted, fitted)])) or covariance[0, 0] <= 0:
        return failure(FitStatus.NOT_CONVERGED, "covariance is not finite", **known)
    # A variance below zero is rounding in a numerically singular inverse (θmax against κ near
    # 90°), not a σ: that parameter's row and column are NaN and it is named as not determined.
    names = _parameter_names(n_ch, options)
    singular = [i for i in np.flatnonzero(fitted) if covariance[i, i] < 0]
    covariance[singular, :] = covariance[:, singular] = np.nan
    singular_names = tuple(names[i] for i in singular)
    if chi2_dof > options.max_chi2_dof:
        return failure(
            FitStatus.BAD_FIT,
            f"χ²/dof = {chi2_dof:.1f} > {options.max_chi2_dof:g}: the ring-down model does not describe these data",
            **known,
        )
    kappa = step.coef[:, 0]
    signal_power = float(np.mean(kappa**2) * np.var(step.shape.g))
    resid_power = float(np.sum(step.residual**2))
    total = float(np.sum((y - y.mean(axis=1, keepdims=True)) ** 2))
    # Sign convention: θmax > 0 and φ in (−π, π]; flipping both leaves x(t) unchanged.
    amp, phi = q[2], q[3]
    if amp < 0:
        amp, phi = -amp, phi + math.pi
    if not free[AMPLITUDE]:  # held at a bound: a number the data did not give
        amp = math.nan
    if singular_names:
        note = "; ".join(
            filter(None, [note, f"{', '.join(singular_names)} not determined: numerically singular covariance"])
        )
    fit = RingdownFit(
        status=FitStatus.OK,
        message=note,
        theta0_rad=float(problem.theta0 + q[4] if options.theta0_free else problem.theta0),
        theta0_free=options.theta0_free,
        rest_offset_rad=wrapped_rad(q[4]) if options.rest_offset_free and not options.theta0_free else math.nan,
        frequency_hz=float(q[0]),
        frequency_std_hz=float(math.sqrt(covariance[0, 0])),
        frequency_crb_hz=float(math.sqrt(fisher_inv[0, 0])),
        damping_per_s=float(q[1]),
        amplitude_rad=float(amp),
        phase_rad=wrapped_rad(phi),
        kappa_t=float(kappa[0]),
        offset_t=float(step.coef[0, 1]),
        chi2_dof=chi2_dof,
        r_squared=1.0 - resid_power / total if total > 0 else math.nan,
        snr_db=10.0 * math.log10(signal_power / float(np.mean(noise**2))) if signal_power > 0 else -math.inf,
        noise_std_t=float(noise.mean()),
        n_samples=n,
        duration_s=n * problem.dt,
        start_offset_s=start_s,
        parameter_names=tuple(names),
        covariance=covariance,
        pickup=tuple(complex(c) for c in problem.fitted_pickup(q)),
        undetermined=tuple(dict.fromkeys((() if free[AMPLITUDE] else ("amplitude_rad",)) + singular_names)),
    )
    # A number whose σ is not determined is not reported either (the fields of one channel's fit).
    reported: dict[str, Any] = {name: math.nan for name in singular_names if hasattr(fit, name)}
    return dataclasses.replace(fit, **reported) if reported else fit
