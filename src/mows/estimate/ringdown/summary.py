"""A converged fit of K ≥ 1 tones summarised into one :class:`RingdownFit` per probe: the
covariance and the Cramér–Rao bound from the Fisher information (docs/physics.md §11), and
what the data do not determine left out.

Uncertainties. ``frequency_std_hz`` comes from the covariance (JᵀJ)⁻¹·s² with the residual
variance s², ``frequency_crb_hz`` from the Fisher information with the white-noise level
measured from the data alone: the bound of that probe's frequency *in the presence of the
others*, which grows as their frequencies approach. A variance that comes out below zero
(rounding in a numerically singular inverse, θmax against κ near 90°) is not a σ: that
parameter's row and column are NaN and it is named as not determined.

θmax and the rest offset are reported only where the data pin them: their σ within a third of
``FitOptions``' tolerances, no rival minimum of the cost (one probe, :mod:`mows.estimate.ringdown.fit`)
within Δχ² = :data:`RIVAL_CHI2`, θmax not held at a bound. Where the model has no rest offset
and the pickup's absolute scale is known, θmax is the swing the signal's size gives
(:func:`swing_from_signal_rad`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import brentq

from mows.estimate.ringdown.problem import (
    AMPLITUDE,
    NONLINEAR,
    Evaluation,
    RingdownProblem,
    evaluate,
    fisher_information,
    scaled_inverse,
)
from mows.estimate.ringdown.types import FitOptions, FitStatus, ProbeLine, RingdownFit, failure, parameter_std

# Another minimum of the cost closer than this (Δχ², in units of χ²/dof) is a rival: noise
# reverses the order of two minima 25 apart less than once in 150 (Δχ²'s σ is 2·√Δχ²).
RIVAL_CHI2 = 25.0
# A number is reported where its tolerance is this many σ: beyond it lies 1 fit in 370.
DETERMINED_SIGMAS = 3.0
OFFSET = len(NONLINEAR)  # a tone's index of the rest offset ε (or θ0's error) when it is free


def wrapped_rad(angle_rad: float) -> float:
    """The angle in (−π, π]."""
    return float(-((math.pi - angle_rad) % math.tau - math.pi)) + 0.0  # + 0.0: no −0.0


def known_of(line: ProbeLine, options: FitOptions) -> dict[str, Any]:
    """What a fit of ``line`` reports even when it fails."""
    return {"theta0_rad": float(line.theta0_rad), "theta0_free": options.theta0_free, "probe_id": line.probe_id}


def failures(status: FitStatus, message: str, lines: Sequence[ProbeLine], options: FitOptions) -> list[RingdownFit]:
    """The same failure for every probe of ``lines``."""
    return [failure(status, message, **known_of(line, options)) for line in lines]


def parameter_names(problem: RingdownProblem, options: FitOptions) -> list[str]:
    """One tone's parameters, as its :attr:`RingdownFit.covariance` orders them."""
    names = list(NONLINEAR)
    if problem.offset_free:
        names.append("theta0_rad" if options.theta0_free else "rest_offset_rad")
    n_channels = problem.y.shape[0]
    for c in range(n_channels):
        suffix = "" if n_channels == 1 else f"_{c + 1}"
        names += [f"kappa_t{suffix}", f"offset_t{suffix}"]
    return names


def summarise(
    step: Evaluation,
    problem: RingdownProblem,
    free: NDArray[np.bool_],
    lines: Sequence[ProbeLine],
    options: FitOptions,
    start_s: float,
) -> list[RingdownFit]:
    """One fit per tone of the converged ``step`` (``free``: the parameters not held at a
    bound), in the order of ``lines``."""
    per_tone = problem.per_tone
    stiff = [
        step.q[k * per_tone] >= options.min_frequency_fraction * line.expected_frequency_hz
        for k, line in enumerate(lines)
    ]
    fisher = fisher_information(step, problem.weights)
    fitted = np.concatenate([free, np.ones(fisher.shape[0] - free.size, bool)])
    fisher_inv = np.full(fisher.shape, np.nan)
    try:
        fisher_inv[np.ix_(fitted, fitted)] = scaled_inverse(fisher[np.ix_(fitted, fitted)])
    except np.linalg.LinAlgError:
        message = "singular Fisher information: parameters not identifiable"
        return _unless_soft(stiff, step, lines, options, FitStatus.NOT_CONVERGED, message)
    chi2_dof = step.cost / (step.residual.size - int(fitted.sum()))
    covariance = fisher_inv * chi2_dof
    if not np.all(np.isfinite(covariance[np.ix_(fitted, fitted)])):
        return _unless_soft(stiff, step, lines, options, FitStatus.NOT_CONVERGED, "covariance is not finite")
    if chi2_dof > options.max_chi2_dof:
        message = (
            f"χ²/dof = {chi2_dof:.1f} > {options.max_chi2_dof:g}: the ring-down model does not describe these data"
        )
        return _unless_soft(stiff, step, lines, options, FitStatus.BAD_FIT, message)
    # A variance below zero is rounding in a numerically singular inverse (θmax against κ near
    # 90°), not a σ: that parameter's row and column are NaN and it is named as not determined.
    singular = np.zeros(fitted.size, bool)
    singular[fitted] = np.diag(covariance)[fitted] < 0
    covariance[singular, :] = covariance[:, singular] = np.nan
    total = float(np.sum((problem.y - problem.y.mean(axis=1, keepdims=True)) ** 2))
    r_squared = 1.0 - float(np.sum(step.residual**2)) / total if total > 0 else math.nan
    fits = []
    for k, line in enumerate(lines):
        if not stiff[k]:
            fits.append(_soft(step.q[k * per_tone], line, options))
            continue
        rows = _tone_rows(problem, k)
        fits.append(
            _tone_fit(
                k,
                line,
                step,
                problem,
                free[k * per_tone : (k + 1) * per_tone],
                covariance[np.ix_(rows, rows)],
                singular[rows],
                float(fisher_inv[rows[0], rows[0]]),
                chi2_dof,
                r_squared,
                options,
                start_s,
            )
        )
    return fits


def _tone_rows(problem: RingdownProblem, tone: int) -> list[int]:
    """Tone's rows of the Fisher information: its q, then its κ and B_DC of each channel."""
    per_tone, n_tones = problem.per_tone, problem.tones
    nonlinear = n_tones * per_tone
    rows = list(range(tone * per_tone, (tone + 1) * per_tone))
    for c in range(problem.y.shape[0]):
        rows += [nonlinear + (n_tones + 1) * c + tone, nonlinear + (n_tones + 1) * c + n_tones]
    return rows


def _soft(frequency_hz: float, line: ProbeLine, options: FitOptions) -> RingdownFit:
    return failure(
        FitStatus.NEGATIVE_STIFFNESS,
        f"fitted frequency {frequency_hz:.3f} Hz is below {options.min_frequency_fraction:g} × the expected "
        f"{line.expected_frequency_hz:.2f} Hz: the restoring spring is (nearly) cancelled (k ≤ 0 beyond B = −kM/m)",
        **known_of(line, options),
    )


def _unless_soft(
    stiff: list[bool],
    step: Evaluation,
    lines: Sequence[ProbeLine],
    options: FitOptions,
    status: FitStatus,
    message: str,
) -> list[RingdownFit]:
    """Every probe failed with ``status``, but a probe below its stiffness limit as such."""
    per_tone = step.q.size // len(lines)
    return [
        failure(status, message, **known_of(line, options)) if ok else _soft(step.q[k * per_tone], line, options)
        for k, (line, ok) in enumerate(zip(lines, stiff))
    ]


def _tone_fit(
    k: int,
    line: ProbeLine,
    step: Evaluation,
    problem: RingdownProblem,
    free: NDArray[np.bool_],
    covariance: NDArray[np.float64],
    singular: NDArray[np.bool_],
    crb_variance: float,
    chi2_dof: float,
    r_squared: float,
    options: FitOptions,
    start_s: float,
) -> RingdownFit:
    known = known_of(line, options)
    if not covariance[0, 0] > 0:
        return failure(FitStatus.NOT_CONVERGED, "covariance is not finite", **known)
    q = step.q[k * problem.per_tone : (k + 1) * problem.per_tone]
    names = parameter_names(problem, options)
    singular_names = tuple(name for name, held in zip(names, singular) if held)
    note = (
        ""
        if free[AMPLITUDE]
        else (
            f"θmax not determined (the fit ran to its bound {math.degrees(abs(q[AMPLITUDE])):.1f}°): "
            "the data do not separate θmax from κ; f is unaffected"
        )
    )
    # θmax said by name, as every other reason it is not reported says it.
    others = [name for name in singular_names if name != "amplitude_rad"]
    reasons = [note] if note else []
    if "amplitude_rad" in singular_names:
        reasons.append("θmax not determined: numerically singular covariance")
    if others:
        reasons.append(f"{', '.join(others)} not determined: numerically singular covariance")
    note = "; ".join(reasons)
    # Sign convention: θmax > 0 and φ in (−π, π]; flipping both leaves x(t) unchanged.
    amp, phi = q[AMPLITUDE], q[3]
    if amp < 0:
        amp, phi = -amp, phi + math.pi
    if not free[AMPLITUDE]:  # held at a bound: a number the data did not give
        amp = math.nan
    kappa = step.coef[:, k]
    noise = 1.0 / problem.weights
    signal_power = float(np.mean(kappa**2) * np.var(step.g[k]))
    n = problem.y.shape[1]
    offset = q[OFFSET] if problem.offset_free else 0.0
    pickup = problem.fitted_pickup(step.q, k)[: line.pickup_series(options).size]
    fit = RingdownFit(
        status=FitStatus.OK,
        message=note,
        theta0_rad=float(line.theta0_rad + offset if options.theta0_free else line.theta0_rad),
        theta0_free=options.theta0_free,
        rest_offset_rad=wrapped_rad(offset) if problem.offset_free and not options.theta0_free else math.nan,
        frequency_hz=float(q[0]),
        frequency_std_hz=float(math.sqrt(covariance[0, 0])),
        frequency_crb_hz=float(math.sqrt(crb_variance)),
        damping_per_s=float(q[1]),
        amplitude_rad=float(amp),
        phase_rad=wrapped_rad(phi),
        kappa_t=float(kappa[0]),
        offset_t=float(step.coef[0, -1]),
        chi2_dof=chi2_dof,
        r_squared=r_squared,
        snr_db=10.0 * math.log10(signal_power / float(np.mean(noise**2))) if signal_power > 0 else -math.inf,
        noise_std_t=float(noise.mean()),
        n_samples=n,
        duration_s=n * problem.dt,
        start_offset_s=start_s,
        parameter_names=tuple(names),
        covariance=covariance,
        pickup=tuple(complex(c) for c in pickup),
        undetermined=tuple(dict.fromkeys((() if free[AMPLITUDE] else ("amplitude_rad",)) + singular_names)),
        probe_id=line.probe_id,
    )
    # A number whose σ is not determined is not reported either (the fields of one probe's fit).
    reported: dict[str, Any] = {name: math.nan for name in singular_names if hasattr(fit, name)}
    return dataclasses.replace(fit, **reported) if reported else fit


# --- what the data do not determine ----------------------------------------------------------
def offset_apart(q: NDArray[np.float64], other: NDArray[np.float64], options: FitOptions) -> bool:
    return abs(wrapped_rad(q[OFFSET] - other[OFFSET])) > options.rest_offset_tolerance_rad / 2


def amplitude_apart(q: NDArray[np.float64], other: NDArray[np.float64], options: FitOptions) -> bool:
    return abs(abs(q[AMPLITUDE]) - abs(other[AMPLITUDE])) > options.amplitude_tolerance_rad / 2


def undetermined_removed(
    fit: RingdownFit, problem: RingdownProblem, cost: float, others: list[Evaluation], options: FitOptions
) -> RingdownFit:
    """``fit`` with θmax and the rest offset NaN, the reason said, where the data do not pin
    them within ``options``' tolerances: another minimum of the cost (``others``, coarse
    optima of a one-tone problem) fits within Δχ² = RIVAL_CHI2 (in units of the fit's χ²/dof)
    and differs by more than half the tolerance, or the tolerance is less than
    DETERMINED_SIGMAS of the parameter's σ."""
    q = np.array([fit.frequency_hz, fit.damping_per_s, fit.amplitude_rad, fit.phase_rad, fit.rest_offset_rad])
    rivals = [o.q for o in others if evaluate(problem, o.q, False).cost - cost < RIVAL_CHI2 * fit.chi2_dof]
    changes: dict[str, Any] = {}
    reasons: list[str] = []
    if not math.isfinite(fit.amplitude_rad) and math.isfinite(fit.rest_offset_rad):
        # θmax at its bound, κ unbounded: the offset then only sets the ratio of the lines at f and 2f.
        changes["rest_offset_rad"] = math.nan
        reasons.append("rest offset not determined where θmax is not")
    for name, tolerance, apart in (
        ("amplitude_rad", options.amplitude_tolerance_rad, amplitude_apart),
        ("rest_offset_rad", options.rest_offset_tolerance_rad, offset_apart),
    ):
        value, std = getattr(fit, name), parameter_std(fit.parameter_names, fit.covariance, name)
        if not math.isfinite(value) or name in changes:
            continue
        rival = next((r for r in rivals if apart(q, r, options)), None)
        what = "θmax" if name == "amplitude_rad" else "rest offset"
        if rival is not None:
            other = abs(rival[AMPLITUDE]) if name == "amplitude_rad" else wrapped_rad(rival[OFFSET])
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


# --- the swing from the signal's size --------------------------------------------------------
def with_swing_from_size(fit: RingdownFit, scale_t: float) -> RingdownFit:
    """``fit`` with θmax from its signal's size (:func:`swing_from_signal_rad`) where the pickup's
    absolute scale is known; else ``fit`` as it is. For a model without a rest offset: the
    magnet swings about its rest angle, which such a model leaves out, and the pickup's
    harmonics there pass for a different θmax (tens of percent at 15 mrad), while the size is
    off by only g'(0)/g'(θs), which the sweep's model, knowing θs, takes out
    (:meth:`mows.sweep.shift_model.Ringdowns.start_swing_about_rad`)."""
    if not (fit.ok and math.isfinite(scale_t)):
        return fit
    swing = swing_from_signal_rad(fit, scale_t)
    if not math.isfinite(swing):
        return fit
    if "amplitude_rad" not in fit.undetermined:
        return dataclasses.replace(fit, amplitude_rad=swing)
    message = f"θmax {math.degrees(swing):.2f}° from the signal's size through the pickup's absolute scale"
    return dataclasses.replace(fit, amplitude_rad=swing, undetermined=(), message=message)


SWING_BRACKET_RAD = (1e-4, 0.7)  # within the potential's interval


def swing_from_signal_rad(fit: RingdownFit, scale_t: float) -> float:
    """The swing θmax at the start of a fit's window, from the power of its fitted signal.

    ``scale_t`` times the fit's pickup series (:func:`mows.physics.fluxgate.pickup_scale_t`) is
    the sensors' absolute signal of the swinging magnet in tesla, so the fitted signal's power,
    ``noise_std_t``² × 10^(``snr_db``/10), fixes the swing: the A0 whose ring-down
    A0·e^(−δt)·cos(2πft) through the pickup has that variance over the window. A fit of several
    probes may leave θmax itself undetermined (its shape barely depends on it), but not its
    signal's size. NaN if the fit's numbers do not fix it."""
    power = fit.noise_std_t**2 * 10.0 ** (fit.snr_db / 10.0)
    if not (math.isfinite(power) and power > 0 and fit.pickup):
        return math.nan
    pickup = scale_t * np.asarray(fit.pickup, complex)
    t = np.linspace(0.0, fit.duration_s, fit.n_samples, endpoint=False)
    carrier = np.exp(-fit.damping_per_s * t) * np.cos(2.0 * math.pi * fit.frequency_hz * t)

    def excess(swing: float) -> float:
        # The pickup series Σ p_k·e^(ik·θ(t)) by Horner's rule in z = e^(iθ(t)): one complex
        # exponential per sample instead of one per sample and order, and no BLAS call (whose
        # threads only spin on a loaded machine); the same numbers to rounding.
        z = np.exp(1j * swing * carrier)
        signal = np.full(z.shape, pickup[-1])
        for coefficient in pickup[-2::-1]:
            signal = signal * z + coefficient
        return float(np.var(signal.real)) - power

    low, high = SWING_BRACKET_RAD
    if not excess(low) < 0.0 < excess(high):
        return math.nan
    return float(brentq(excess, low, high, xtol=1e-7))
