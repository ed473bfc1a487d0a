"""The fit of K ≥ 1 probes ringing down in one window, Eqs. S2, S11, S12, at the Cramér–Rao
bound: :func:`fit_ringdowns`, and :func:`fit_ringdown`, the fit of one; :func:`fit_tuning`, the
cycle sequencer's tuning fit.

Its options and result types are :mod:`mows.estimate.ringdown.types` (imported here too).

Model of one channel:

    S(t) = Σ_k κ_k·g_k(ε + x_k(t)) + B_DC,   x_k(t) = θmax,k·e^(−δ_k t)·cos(2πf_k t + φ_k)
    (Eq. S2, t = 0 at the first fitted sample),   g_k(x) = Σ_j Re(C_k,j·e^(ijx)).

Probes that share a pair of fluxgates are told apart by their frequencies; each has its own
pickup series g_k and its own κ_k, and the sensor sees their sum. A fit of one probe on the
mixed signal would not reach the bound: its model has no room for the neighbour, whose line
leaks into its frequency (tests/estimate/test_ringdown_joint.py).

ε is the rest-angle offset θs − θ0 (``FitOptions.rest_offset_free``, on by default): a field across
the probe, gravity in the plane or a gradient deflects the rest angle, and the probe swings about
θs, not θ0. Without ε, κ and θmax trade off against it (θmax 3.5°–74° for a true 11°–21° in a
strong perpendicular field); f is nearly orthogonal to it (the bound grows by < 1 %, the fit's
time by 0–12 %). It is fitted, and its several minima searched, for one probe only: with
several, each probe's (θmax, ε) minima would multiply into a search over 2K dimensions, for
numbers f does not need; there each swings about its commanded θ0, as the paper's model has
it, and θmax comes from the signal's size where the pickup's absolute scale is known
(:func:`mows.estimate.ringdown.summary.swing_from_signal_rad`).

g is the sensor's signal as a function of the deflection, normalised by κ. The paper's model
(Eq. S11, a sensor along (a, b) and a magnet turning in place) is the single term
C_1 = (2a + ib)·e^(iθ0), i.e. g = 2a·cos(θ0 + x) − b·sin(θ0 + x); its sensors have
(a, b) = (0, 1), which is Eq. S12. On a real lever the magnet also moves, and the exact
pickup (:func:`mows.physics.fluxgate.pickup_harmonics`) adds harmonics of relative size ~(3l/r)^k
(0.11 for k = 2 in the paper's set-up): pass them as ``FitOptions.pickup`` or a probe's
``ProbeLine.pickup``. θ0 is taken from the excitation state (the commanded orientation), or, in
the paper's model of one probe, fitted.

Estimator. Least squares is the maximum-likelihood estimator for white Gaussian noise, and
reaches the Cramér–Rao bound (docs/physics.md §11) once the fit is converged at full rate. The
fit runs in three stages so that this costs 1–2 ms for one probe (0.5 s at 20 kS/s):

1. a start from the zero-padded spectrum (:mod:`mows.estimate.ringdown.start`): each probe's
   line at f, or at 2f (near 90° the signal is mostly there), its phase, θmax 0.3 rad and the
   probe's damping guess; every combination of the candidate phases is tried;
2. Levenberg–Marquardt with variable projection (:mod:`mows.estimate.ringdown.problem`) on
   every D-th sample. Subsampling keeps white noise white and the model's harmonics below the
   new Nyquist frequency, so this stage lands within a few standard deviations of the optimum
   at 1/D of the cost. In a strong field the cost of one probe over (θmax, ε) has several
   minima (near θ0 = 90° the signal is nearly even in the deflection, and κ trades off against
   θmax): this stage is also started from every minimum of a grid search over the whole range
   (:mod:`mows.estimate.ringdown.offset`), and from the best one's mirror images, with κ > 0.
   The search (2–3 ms, more than the rest of the fit) runs only where the data can pin θmax or
   ε: where the local optimum's σ of both, scaled to the full rate, exceeds the reporting
   limit below, the fit goes on from the local optimum and reports both as not determined
   (another minimum might pin one; not reporting a number is always allowed, a wrong one
   never). Should the full-rate fit pin one after all, the search runs then;
3. Gauss–Newton steps on all samples until the step is < 1e-3 σ in every parameter. The
   Jacobian of the last step gives the covariance and the Fisher information
   (:mod:`mows.estimate.ringdown.summary`).

What the data do not determine is not reported. θmax and ε are NaN, named in
``RingdownFit.undetermined`` and the reason in its message, where another minimum that differs
by more than half their tolerance (``FitOptions``: 1° and 0.5°) fits within Δχ² = 25, or where
their σ exceeds a third of it. In fields up to 5 mT and gradients up to 50 mT/m the reported
ones are within the tolerance (tests/estimate/test_ringdown_rest_offset.py); a 0.25–0.5 s
ring-down there determines ε in a few percent of the fits and θmax (σ ≥ 0.35°) in none.

Nor is a probe of several whose line is not in the data (it did not ring): its tone would fit
noise or share a neighbour's line, at an OK status (:mod:`mows.estimate.ringdown.absent`). Where
the coarse fit without one tone is worse by less than ABSENT_CHI2, the probe none of the remaining lines is nearest is
NO_OSCILLATION and the others are fitted without it; a probe whose fitted line is nearer another
probe's expected frequency than its own is NO_OSCILLATION too.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Iterable, Sequence
from typing import SupportsFloat

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mows.estimate.ringdown.absent import absent_tone, own_lines
from mows.estimate.ringdown.offset import offset_starts
from mows.estimate.ringdown.problem import (
    AMPLITUDE,
    Evaluation,
    RingdownProblem,
    evaluate,
    finite_cost,
    padded_pickups,
    scaled_inverse,
    variable_projection,
)
from mows.estimate.ringdown.start import line_starts, white_noise_std
from mows.estimate.ringdown.summary import (
    DETERMINED_SIGMAS,
    OFFSET,
    amplitude_apart,
    failures,
    known_of,
    offset_apart,
    summarise,
    undetermined_removed,
    with_swing_from_size,
)
from mows.estimate.ringdown.types import FitOptions, FitStatus, ProbeLine, RingdownFit, failure
from mows.estimate.ringdown.window import combine_channels, usable_window

START_AMPLITUDE_RAD = 0.3  # θmax to start from (17°, a typical swing after the excitation)


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
    """Fit one free ring-down: :func:`fit_ringdowns` of one probe, its pickup ``options``'.

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
    line = ProbeLine(0, float(theta0_rad), _as_float(expected_frequency_hz), None, damping_guess_per_s)
    if not (math.isfinite(line.expected_frequency_hz) and line.expected_frequency_hz > 0):
        return failure(
            FitStatus.BAD_SAMPLE_RATE,
            f"expected frequency {line.expected_frequency_hz!r} Hz is not positive",
            **known_of(line, options),
        )
    return fit_ringdowns(samples, sample_rate_hz, [line], saturated, options, coil_off_skip_s)[0]


def fit_ringdowns(
    samples: ArrayLike,
    sample_rate_hz: float,
    lines: Sequence[ProbeLine],
    saturated: ArrayLike | None = None,
    options: FitOptions = FitOptions(),
    coil_off_skip_s: float = 0.0,
) -> list[RingdownFit]:
    """Fit the ring-downs of the K ≥ 1 probes in ``lines`` ringing in one window, jointly; one
    :class:`RingdownFit` per probe, in the order of ``lines``, each carrying its ``probe_id``.

    ``samples`` (n,) or (n, 2), tesla, sample 0 at the coils' switch-off; ``saturated`` a mask
    like it; samples before ``coil_off_skip_s`` are not used. Bad data give non-OK fits with the
    reason (never an exception); a malformed list of probes (none, a repeated id, a non-positive
    frequency, θ0 fitted for several) raises ValueError naming it.
    """
    _check_lines(lines, options)
    fs = _as_float(sample_rate_hz)
    if not (math.isfinite(fs) and fs > 0):
        return failures(
            FitStatus.BAD_SAMPLE_RATE, f"sample rate {sample_rate_hz!r} Hz is not a positive number", lines, options
        )
    highest = max(line.expected_frequency_hz for line in lines)
    if highest * (1 + options.search_fraction) * 2 * 3 > fs / 2:
        message = (
            f"sample rate {fs:g} Hz cannot resolve a ring-down near {highest:g} Hz "
            f"and its harmonics (needs > {12 * highest * (1 + options.search_fraction):.0f} Hz)"
        )
        return failures(FitStatus.BAD_SAMPLE_RATE, message, lines, options)
    data = np.asarray(samples, float)
    if data.ndim not in (1, 2) or data.shape[0] == 0:
        return failures(FitStatus.TOO_SHORT, f"no samples (shape {data.shape})", lines, options)
    if not np.all(np.isfinite(data)):
        bad = int(np.count_nonzero(~np.isfinite(data)))
        return failures(FitStatus.INVALID_SAMPLES, f"{bad} NaN or infinite samples in the ring-down", lines, options)
    mask = np.zeros(data.shape, bool) if saturated is None else np.asarray(saturated, bool)
    start, stop = usable_window(mask, int(round(coil_off_skip_s * fs)))
    lowest = min(line.expected_frequency_hz for line in lines)
    min_samples = int(math.ceil(options.min_periods * fs / lowest))
    if stop - start < min_samples:
        why = FitStatus.SATURATED if mask.any() else FitStatus.TOO_SHORT
        message = (
            f"{stop - start} usable samples ({(stop - start) / fs * 1e3:.1f} ms) after removing "
            f"{int(mask.reshape(len(mask), -1).any(axis=1).sum())} saturated samples; "
            f"need {min_samples} ({options.min_periods:g} periods)"
        )
        return failures(why, message, lines, options)
    y = combine_channels(data[start:stop], options.channels)
    return own_lines(_fit_window(y, fs, lines, options, start / fs), lines, options)


def fit_tuning(
    samples: ArrayLike,
    sample_rate_hz: float,
    theta0_rad: Sequence[float],
    expected_frequency_hz: Sequence[float],
    saturated: ArrayLike | None = None,
) -> list[RingdownFit]:
    """The cycle sequencer's tuning fit (:data:`mows.device.cycle.phases.TuningFit`): the probes
    ringing in one ring-down, each at its θ0 and expected at its drive's frequency (in one
    order), fitted jointly by :func:`fit_ringdowns`; one fit per probe, in that order."""
    lines = [
        ProbeLine(k, float(theta0), float(frequency_hz))
        for k, (theta0, frequency_hz) in enumerate(zip(theta0_rad, expected_frequency_hz, strict=True))
    ]
    return fit_ringdowns(samples, sample_rate_hz, lines, saturated)


def _check_lines(lines: Sequence[ProbeLine], options: FitOptions) -> None:
    if len(lines) == 0:
        raise ValueError("the fit needs at least one probe")
    ids = [line.probe_id for line in lines]
    if len(set(ids)) != len(ids):
        raise ValueError(f"probe ids {ids} repeat: each probe needs its own")
    for line in lines:
        if not (math.isfinite(line.expected_frequency_hz) and line.expected_frequency_hz > 0):
            raise ValueError(
                f"probe {line.probe_id}: expected frequency {line.expected_frequency_hz!r} Hz is not positive"
            )
    if len(lines) > 1 and options.theta0_free:
        raise ValueError(f"theta0_free fits the θ0 of one probe; {len(lines)} probes share this window")


def _problem(y: NDArray[np.float64], fs: float, lines: Sequence[ProbeLine], options: FitOptions) -> RingdownProblem:
    """The fit's problem: the rest offset (or θ0's error) free for one probe only (module docstring)."""
    noise = np.array([white_noise_std(ch) for ch in y])
    if np.any(noise <= 0):  # noiseless, or quantised to a constant: weight channels equally
        noise = np.full(y.shape[0], max(float(np.ptp(y)) * 1e-9, 1e-30))
    pickups = padded_pickups([line.pickup_series(options) for line in lines])
    offset_free = options.offset_free and len(lines) == 1
    return RingdownProblem(np.ascontiguousarray(y, float), 1.0 / noise, 1.0 / fs, pickups, offset_free)


def _coarse_start(
    problem: RingdownProblem, lines: Sequence[ProbeLine], options: FitOptions
) -> tuple[RingdownProblem, NDArray[np.float64] | None]:
    """The subsampled problem and the best spectral start on it, or (coarse, None): every
    combination of the tones' candidate phases is tried (2^K for lines found at f: 16 for four
    probes) and the cheapest kept."""
    highest = max(line.expected_frequency_hz for line in lines)
    coarse = problem.subsampled(max(1, int(1.0 / problem.dt // (16.0 * highest))))
    candidates = line_starts(coarse.y.sum(axis=0), 1.0 / coarse.dt, lines, options)
    if candidates is None:
        return coarse, None
    extra = [0.0] if problem.offset_free else []  # the rest offset (or θ0's error) starts at 0
    starts = (_start_q(combo, lines, extra) for combo in itertools.product(*candidates))
    return coarse, min(starts, key=lambda q: finite_cost(evaluate(coarse, q, False).cost))


def _start_q(
    combo: Sequence[tuple[float, float]], lines: Sequence[ProbeLine], extra: list[float]
) -> NDArray[np.float64]:
    """q at each tone's (f, φ) of ``combo``: its damping guess, θmax START_AMPLITUDE_RAD, ``extra``."""
    return np.concatenate(
        [[f, line.damping_guess_per_s, START_AMPLITUDE_RAD, phase, *extra] for (f, phase), line in zip(combo, lines)]
    )


def starting_point(
    samples: ArrayLike,
    sample_rate_hz: float,
    theta0_rad: float,
    expected_frequency_hz: float,
    options: FitOptions = FitOptions(),
    damping_guess_per_s: float = 1.8,
) -> NDArray[np.float64] | None:
    """The point the fit of one probe starts from: (f, δ, θmax, φ, [ε,] κ, B_DC) of the first
    channel, from the spectral stage, or None if no line is found (ε: the rest offset, or θ0's
    error, when ``options`` fit one). For comparisons with other optimisers."""
    lines = [ProbeLine(0, float(theta0_rad), float(expected_frequency_hz), None, damping_guess_per_s)]
    problem = _problem(combine_channels(samples, options.channels), float(sample_rate_hz), lines, options)
    _, q0 = _coarse_start(problem, lines, options)
    return None if q0 is None else np.concatenate([q0, evaluate(problem, q0, False).coef[0]])


def _as_float(value: SupportsFloat | str) -> float:
    """A number from a parameter that may be missing or malformed; NaN when it is not one."""
    try:
        return float(value)
    except (TypeError, ValueError):
        return math.nan


def _fit_window(
    y: NDArray[np.float64], fs: float, lines: Sequence[ProbeLine], options: FitOptions, start_s: float
) -> list[RingdownFit]:
    problem = _problem(y, fs, lines, options)
    coarse, q0 = _coarse_start(problem, lines, options)
    if q0 is None:
        bands = " or ".join(f"{line.expected_frequency_hz:.2f} Hz" for line in lines)
        message = (
            f"no spectral line near {bands} or its double stands above the noise floor (×{options.detection_snr:g})"
        )
        return failures(FitStatus.NO_OSCILLATION, message, lines, options)
    step, _, _, _ = variable_projection(coarse, q0, options.max_iterations, tol_chi2=1e-2)
    if len(lines) > 1:
        absent = absent_tone(coarse, step, lines, options)
        if absent is not None:
            k, message = absent
            present = _fit_window(y, fs, [line for i, line in enumerate(lines) if i != k], options, start_s)
            present.insert(k, failure(FitStatus.NO_OSCILLATION, message, **known_of(lines[k], options)))
            return present
    fits: list[RingdownFit] | None = None
    searched = problem.offset_free and not options.theta0_free
    if searched and not _pinned_locally(step, coarse, problem, options):
        # Neither θmax nor ε has σ within its reporting limit at the local optimum: the search
        # over (θmax, ε) could only move numbers that are not reported, at twice the fit's cost.
        # Kept only if the full-rate fit agrees (both NaN); else the search runs as below.
        fits = _refined(problem, step.q, [], lines, options, start_s)
        fit = fits[0]
        if not (fit.ok and math.isnan(fit.amplitude_rad) and math.isnan(fit.rest_offset_rad)):
            fits = None
    if fits is None:
        others: list[Evaluation] = []
        if searched:
            step, *others = _offset_minima(coarse, step, options)
        fits = _refined(problem, step.q, others, lines, options, start_s)
    if fits[0].status == FitStatus.NOT_CONVERGED and searched:
        # The offset has no handle (near 90° the signal is even in it, at a small θmax it is
        # lost in κ): the swing about θ0, as the paper's model has it, and the reason said.
        fallback = dataclasses.replace(options, rest_offset_free=False)
        fits = _fit_window(y, fs, lines, fallback, start_s)
        # θmax about θ0 is not the swing about a rest angle the data did not give.
        note = "rest offset and θmax not determined: fitted without the offset"
        return [
            dataclasses.replace(
                fit,
                amplitude_rad=math.nan,
                message="; ".join(filter(None, [note, fit.message])),
                undetermined=tuple(dict.fromkeys(("rest_offset_rad", "amplitude_rad", *fit.undetermined))),
            )
            if fit.ok
            else fit
            for fit in fits
        ]
    return fits


def _refined(
    problem: RingdownProblem,
    start: NDArray[np.float64],
    others: list[Evaluation],
    lines: Sequence[ProbeLine],
    options: FitOptions,
    start_s: float,
) -> list[RingdownFit]:
    """The full-rate fit from a coarse optimum ``start`` (within a few σ of the full-rate one:
    started as Gauss–Newton), summarised, with what ``others`` (rival coarse optima of one
    probe) or the σ leave undetermined removed."""
    step, converged, iters, free = variable_projection(problem, start, options.max_iterations, 1e-4, damping=1e-6)
    if not converged:  # a weakly determined θmax or rest offset can crawl: the cautious Marquardt λ
        step, converged, iters, free = variable_projection(problem, start, options.max_iterations, 1e-4, damping=1e-3)
    if not converged:
        return failures(FitStatus.NOT_CONVERGED, f"the fit did not converge in {iters} iterations", lines, options)
    fits = summarise(step, problem, free, lines, options, start_s)
    fits = [undetermined_removed(fit, problem, step.cost, others, options) if fit.ok else fit for fit in fits]
    if problem.offset_free:
        return fits
    return [with_swing_from_size(fit, line.pickup_scale_t) for fit, line in zip(fits, lines)]


def _pinned_locally(step: Evaluation, coarse: RingdownProblem, problem: RingdownProblem, options: FitOptions) -> bool:
    """Whether θmax or ε could be reported from the coarse optimum ``step`` of one probe: its σ
    at the full rate (the coarse covariance scaled by the ratio of the sample counts, the noise
    level as the weights have it) within tolerance/DETERMINED_SIGMAS. A numerically singular
    normal matrix pins neither."""
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


def _offset_minima(coarse: RingdownProblem, step: Evaluation, options: FitOptions) -> list[Evaluation]:
    """The distinct coarse optima of one probe reached from every minimum of the cost over the
    rest offset (:func:`mows.estimate.ringdown.offset.offset_starts`), from the local ``step``
    and from the best one's mirror images, lowest cost first. κ < 0 turns g into −g, the same
    waveform as a pickup turned by another offset: such optima are left out unless there is no
    other."""
    solutions = [step]

    def refine(starts: Iterable[NDArray[np.float64]]) -> None:
        solutions.extend(
            variable_projection(coarse, start, options.max_iterations, tol_chi2=1e-2)[0] for start in starts
        )

    def distinct() -> list[Evaluation]:
        physical = [s for s in solutions if np.all(s.coef[:, 0] > 0)] or solutions
        kept: list[Evaluation] = []
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


def _agree(q: NDArray[np.float64], other: NDArray[np.float64], options: FitOptions) -> bool:
    return not (offset_apart(q, other, options) or amplitude_apart(q, other, options))
