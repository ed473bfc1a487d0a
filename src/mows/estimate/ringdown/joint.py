"""One fit of K probes ringing down together in the same window, at the Cramér–Rao bound.

Probes that share a pair of fluxgates are told apart by their frequencies. Each rings down as
one probe does (:mod:`mows.estimate.ringdown`, Eqs. S2, S11, S12), with its own pickup series
g_k (the lever-aware harmonics of :func:`mows.physics.fluxgate.pickup_harmonics`, or the paper's
single term) and its own κ_k; the sensor sees their sum:

    S(t) = Σ_k κ_k·g_k(x_k(t)) + B_DC,   x_k(t) = θmax,k·e^(−δ_k t)·cos(2πf_k t + φ_k).

Estimator. Variable projection (Golub–Pereyra, Kaufman's Jacobian), as for one probe: for any
nonlinear parameters q = (f_k, δ_k, θmax,k, φ_k) of all probes, the κ_k and B_DC of each
channel follow by linear least squares on {g_1 … g_K, 1}, and Levenberg–Marquardt moves q on
the projected residual, first on every D-th sample, then on all of them. Least squares is the
maximum-likelihood estimator for white Gaussian noise, so the joint fit reaches the bound of the
joint model; a fit of one probe on the mixed signal does not (its model has no room for the
neighbour, whose line leaks into its frequency: tests/estimator/test_ringdown_joint.py).

Start. The lines at f are found one at a time: the strongest peak of the zero-padded spectrum
of what is left in the probes' bands, refined by Gaussian interpolation, its damped sinusoid
fitted and subtracted (a line of a strong probe would otherwise hide a weak neighbour's in
its skirt). The lines are assigned to the probes in order of frequency; a probe whose line is
not found starts at its expected frequency. φ_k starts at the line's phase or a half-turn from
it, whichever fits better; θmax,k at 0.3 rad, δ_k at the guess.

The swing is about the commanded θ0 (no rest offset, as the paper's model has it): the rest
offset's several minima (:mod:`mows.estimate.ringdown.offset`) are not searched here. θmax is
kept within the one-probe fit's bounds. Where the pickup's absolute scale is known, the θmax
reported is the swing the signal's size gives through the pickup about the undeflected lever
(:func:`start_swing_rad`); elsewhere the fitted one, and only where its σ is below a third of
the one-probe fit's tolerance (1°); otherwise (or at a bound) NaN, named in ``undetermined``.

Uncertainties. Per probe, ``frequency_std_hz`` from the joint covariance (JᵀJ)⁻¹·s², and
``frequency_crb_hz`` from the joint Fisher information with the white-noise level measured from
the data alone: the bound for that probe *in the presence of the others*, which grows as their
frequencies approach (:func:`joint_cramer_rao_hz`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
import numpy.typing
from scipy.optimize import brentq

from mows.estimate.ringdown.fit import combine_channels, usable_window, wrapped_rad
from mows.estimate.ringdown.problem import (
    AMPLITUDE,
    AMPLITUDE_BOUNDS_RAD,
    NONLINEAR,
    RingdownProblem,
    evaluate,
    scaled_inverse,
)
from mows.estimate.ringdown.start import spectral_peak, white_noise_std, windowed_spectrum
from mows.estimate.ringdown.types import FitOptions, FitStatus, RingdownFit, failure
from mows.physics.fluxgate import paper_pickup

TWO_PI = 2.0 * math.pi
P = len(NONLINEAR)  # nonlinear parameters per probe: f, δ, θmax, φ
START_AMPLITUDE_RAD = 0.3
# θmax is reported where the data pin it to a third of the single-probe fit's tolerance.
AMPLITUDE_LIMIT_RAD = FitOptions.amplitude_tolerance_rad / 3.0


@dataclasses.dataclass(frozen=True)
class ProbeLine:
    """What the joint fit is told about one probe.

    probe_id : carried into its :class:`RingdownFit`.
    theta0_rad : its commanded orientation.
    expected_frequency_hz : where its line is, e.g. its excitation frequency.
    pickup : the C_k of its g (:func:`mows.physics.fluxgate.pickup_harmonics`, for the fitted
        channel combination); None: the paper's single term for a sensor along (0, 1).
    damping_guess_per_s : δ to start from.
    pickup_scale_t : the κ that makes ``pickup`` the sensors' signal in tesla
        (:func:`mows.physics.fluxgate.pickup_scale_t`); NaN: unknown. Known, it gives the
        swing from the signal's size where the signal's shape does not (:func:`start_swing_rad`).
    """

    probe_id: int
    theta0_rad: float
    expected_frequency_hz: float
    pickup: tuple | None = None
    damping_guess_per_s: float = 1.8
    pickup_scale_t: float = math.nan

    def pickup_series(self) -> np.ndarray:
        return paper_pickup(self.theta0_rad) if self.pickup is None else np.asarray(self.pickup, complex)


@dataclasses.dataclass(frozen=True)
class JointOptions:
    """How to fit: the channel combination (as :class:`FitOptions`), the spectral band searched
    around each expected frequency (a fraction of it), the line's height over the noise floor
    (power ratio), the fewest periods of the slowest probe, the χ²/dof above which the model is
    rejected, and the Levenberg–Marquardt iteration budget of each stage."""

    channels: str = FitOptions.channels
    search_fraction: float = FitOptions.search_fraction
    detection_snr: float = FitOptions.detection_snr
    min_periods: float = FitOptions.min_periods
    max_chi2_dof: float = FitOptions.max_chi2_dof
    max_iterations: int = 100

    def __post_init__(self) -> None:
        FitOptions(channels=self.channels, search_fraction=self.search_fraction)  # the same checks


# --- the model -------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class JointProblem:
    """Data (C, n) sampled every ``dt`` and the probes' pickups; channel weights 1/σ."""

    y: np.ndarray
    weights: np.ndarray
    dt: float
    theta0_rad: tuple
    pickups: tuple

    @property
    def probes(self) -> int:
        return len(self.pickups)

    def subsampled(self, step: int) -> JointProblem:
        return dataclasses.replace(self, y=np.ascontiguousarray(self.y[:, ::step]), dt=self.dt * step)

    def shapes(self, q: np.ndarray, derivatives: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """g_k (K, n) and ∂g_k/∂q_k (K, P, n) at q = (q_1 … q_K), each from the one-probe kernel."""
        n = self.y.shape[1]
        g, dg = np.empty((self.probes, n)), np.empty((self.probes, P, n))
        for k in range(self.probes):
            single = RingdownProblem(
                np.zeros((1, n)), np.ones(1), self.dt, self.theta0_rad[k], self.pickups[k], offset_free=False
            )
            shape = evaluate(single, q[P * k : P * (k + 1)], derivatives).shape
            g[k] = shape.g
            if derivatives:
                dg[k] = shape.dg_dq
        return g, dg


@dataclasses.dataclass
class JointStep:
    """Everything known at q: the shapes, the linear coefficients (C, K + 1) = (κ_1 … κ_K, B_DC)
    of each channel, the residual (C, n) and the weighted cost."""

    q: np.ndarray
    g: np.ndarray
    dg: np.ndarray
    coef: np.ndarray
    residual: np.ndarray
    cost: float


def _basis(g: np.ndarray) -> np.ndarray:
    return np.vstack([g, np.ones(g.shape[1])]).T  # (n, K + 1)


def project(problem: JointProblem, q: np.ndarray, derivatives: bool = True) -> JointStep:
    g, dg = problem.shapes(q, derivatives)
    basis = _basis(g)
    coef = np.linalg.lstsq(basis, problem.y.T, rcond=None)[0].T  # (C, K + 1)
    residual = problem.y - coef @ basis.T
    cost = float(np.sum((problem.weights[:, None] * residual) ** 2))
    return JointStep(np.asarray(q, float), g, dg, coef, residual, cost)


def _projected_jacobian(problem: JointProblem, step: JointStep) -> np.ndarray:
    """Kaufman's Jacobian of the weighted residual: −w_c·P⊥(κ_k,c·∂g_k/∂q_k), channels stacked."""
    orthonormal = np.linalg.qr(_basis(step.g))[0]
    blocks = []
    for c, weight in enumerate(problem.weights):
        columns = (step.coef[c, : problem.probes, None, None] * step.dg).reshape(problem.probes * P, -1).T
        blocks.append(-weight * (columns - orthonormal @ (orthonormal.T @ columns)))
    return np.vstack(blocks)


def fisher_information(problem: JointProblem, step: JointStep) -> np.ndarray:
    """JᵀJ with weights over all parameters: q (K·P), then (κ_1 … κ_K, B_DC) of each channel."""
    k_p = problem.probes * P
    n_lin = problem.probes + 1
    basis = _basis(step.g)
    fisher = np.zeros((k_p + n_lin * len(problem.weights),) * 2)
    for c, weight in enumerate(problem.weights):
        nonlinear = (step.coef[c, : problem.probes, None, None] * step.dg).reshape(k_p, -1).T
        jacobian = weight * np.hstack([nonlinear, basis])
        idx = np.r_[0:k_p, k_p + n_lin * c : k_p + n_lin * (c + 1)]
        fisher[np.ix_(idx, idx)] += jacobian.T @ jacobian
    return fisher


def joint_cramer_rao_hz(
    n_samples: int,
    sample_rate_hz: float,
    lines: Sequence[ProbeLine],
    truth: Sequence[tuple[float, float, float, float, float]],
    noise_std_t: float,
) -> np.ndarray:
    """(K,): the Cramér–Rao bound of each probe's frequency in the presence of the others, for
    one channel of white noise σ: √[(JᵀJ/σ²)⁻¹]_{f_k f_k} over all parameters of the joint model.
    ``truth[k]`` = (f, δ, θmax, φ, κ) of probe k; t = 0 at the first sample."""
    problem = JointProblem(
        np.zeros((1, int(n_samples))),
        np.array([1.0 / noise_std_t]),
        1.0 / sample_rate_hz,
        tuple(line.theta0_rad for line in lines),
        tuple(line.pickup_series() for line in lines),
    )
    q = np.concatenate([np.asarray(t[:P], float) for t in truth])
    g, dg = problem.shapes(q)
    coef = np.array([[t[P] for t in truth] + [0.0]])
    step = JointStep(q, g, dg, coef, np.empty((1, 0)), math.nan)
    inverse = scaled_inverse(fisher_information(problem, step))
    return np.sqrt(np.diag(inverse)[0 : P * len(lines) : P])


# --- the start -------------------------------------------------------------------------------
def start_lines(y: np.ndarray, fs: float, lines: Sequence[ProbeLine], options: JointOptions) -> list[tuple]:
    """(f, φ) to start each probe from, in the order of ``lines`` (module docstring)."""
    residual = np.asarray(y, float).copy()
    guess = float(np.mean([line.damping_guess_per_s for line in lines]))
    t = np.arange(residual.size) / fs
    pad = 1 << int(math.ceil(math.log2(4 * residual.size)))
    found: list[tuple[float, float]] = []
    floor = math.nan
    for _ in lines:
        spectrum, freqs = windowed_spectrum(residual, fs, pad)
        power = np.abs(spectrum) ** 2
        floor = float(np.median(power[1:])) if not found else floor  # the data's, before any line is taken out
        bands = [line.expected_frequency_hz * (1 + options.search_fraction * np.array([-1, 1])) for line in lines]
        peaks = [spectral_peak(spectrum, power, freqs, low, high, fs / pad) for low, high in bands]
        peak = max((p for p in peaks if p is not None), key=lambda p: p.power, default=None)
        if peak is None or not peak.power > options.detection_snr * floor:
            break
        # The line's damped sinusoid, fitted and taken out, so that the next is found beside it.
        carrier = np.exp((-guess + 1j * TWO_PI * peak.frequency_hz) * t)
        a, b = np.linalg.lstsq(np.column_stack([carrier.real, carrier.imag]), residual - residual.mean(), rcond=None)[0]
        found.append((peak.frequency_hz, float(np.angle(complex(a, -b)))))
        residual -= (complex(a, -b) * carrier).real
    return _assigned(found, lines)


def _assigned(found: list[tuple[float, float]], lines: Sequence[ProbeLine]) -> list[tuple]:
    """The found lines given to the probes in order of frequency; where fewer lines were found,
    each goes to the probe expected nearest it, the others start at their expected frequency."""
    order = np.argsort([line.expected_frequency_hz for line in lines])
    starts: list[tuple] = [(line.expected_frequency_hz, 0.0) for line in lines]
    if len(found) == len(lines):
        for probe, line in zip(order, sorted(found)):
            starts[probe] = line
        return starts
    free = set(range(len(lines)))
    for f, phase in found:
        nearest = min(free, key=lambda i: abs(lines[i].expected_frequency_hz - f))
        starts[nearest] = (f, phase)
        free.discard(nearest)
    return starts


def _starting_q(problem: JointProblem, starts: list[tuple], lines: Sequence[ProbeLine]) -> np.ndarray:
    """The start of every probe, with each φ at the line's phase or a half-turn from it: every
    combination is tried (2^K projections: 16 for four probes) and the cheapest kept."""
    candidates = [
        np.concatenate(
            [
                [f, line.damping_guess_per_s, START_AMPLITUDE_RAD, phase + math.pi * ((flips >> k) & 1)]
                for k, ((f, phase), line) in enumerate(zip(starts, lines))
            ]
        )
        for flips in range(1 << len(lines))
    ]
    costs = np.array([project(problem, q, derivatives=False).cost for q in candidates])
    return candidates[int(np.argmin(np.where(np.isfinite(costs), costs, np.inf)))]


# --- the fit ---------------------------------------------------------------------------------
def fit_ringdowns(
    samples: np.typing.ArrayLike,
    sample_rate_hz: float,
    lines: Sequence[ProbeLine],
    saturated: np.typing.ArrayLike | None = None,
    options: JointOptions = JointOptions(),
    coil_off_skip_s: float = 0.0,
) -> list[RingdownFit]:
    """Fit the ring-downs of all probes in ``lines`` jointly; one :class:`RingdownFit` per probe,
    in the order of ``lines``, each carrying its ``probe_id``.

    ``samples`` (n,) or (n, 2), tesla, sample 0 at the coils' switch-off; ``saturated`` a mask
    like it. Bad data give non-OK fits with the reason (never an exception); a malformed list
    of probes (none, a repeated id, a non-positive frequency) raises ValueError naming it.
    """
    _check_lines(lines)
    fs = float(sample_rate_hz)
    known = [{"theta0_rad": float(line.theta0_rad), "probe_id": line.probe_id} for line in lines]

    def failed(status: FitStatus, message: str) -> list[RingdownFit]:
        return [failure(status, message, **k) for k in known]

    highest = max(line.expected_frequency_hz for line in lines) * (1 + options.search_fraction)
    if not (math.isfinite(fs) and fs > 12 * highest):
        return failed(
            FitStatus.BAD_SAMPLE_RATE, f"sample rate {sample_rate_hz!r} Hz is not above {12 * highest:.0f} Hz"
        )
    data = np.asarray(samples, float)
    if data.ndim not in (1, 2) or data.shape[0] == 0:
        return failed(FitStatus.TOO_SHORT, f"no samples (shape {data.shape})")
    if not np.all(np.isfinite(data)):
        return failed(FitStatus.INVALID_SAMPLES, f"{int(np.count_nonzero(~np.isfinite(data)))} NaN or infinite samples")
    mask = np.zeros(data.shape, bool) if saturated is None else np.asarray(saturated, bool)
    start, stop = usable_window(mask, int(round(coil_off_skip_s * fs)))
    lowest = min(line.expected_frequency_hz for line in lines)
    needed = int(math.ceil(options.min_periods * fs / lowest))
    if stop - start < needed:
        why = FitStatus.SATURATED if mask.any() else FitStatus.TOO_SHORT
        return failed(why, f"{stop - start} usable samples; need {needed} ({options.min_periods:g} periods)")
    y = combine_channels(data[start:stop], options.channels)
    noise = np.array([white_noise_std(channel) for channel in y])
    if np.any(noise <= 0):
        noise = np.full(y.shape[0], max(float(np.ptp(y)) * 1e-9, 1e-30))
    problem = JointProblem(
        np.ascontiguousarray(y),
        1.0 / noise,
        1.0 / fs,
        tuple(line.theta0_rad for line in lines),
        tuple(line.pickup_series() for line in lines),
    )
    starts = start_lines(y.sum(axis=0), fs, lines, options)
    # Every D-th sample first (white noise stays white, the harmonics stay below the new
    # Nyquist frequency), then the full rate from within a few σ of the optimum.
    coarse = problem.subsampled(max(1, int(fs // (16.0 * highest))))
    step = _solve(coarse, _starting_q(coarse, starts, lines), options, tol_chi2=1e-2)
    step = None if step is None else _solve(problem, step.q, options, tol_chi2=1e-4)
    if step is None:
        return failed(FitStatus.NOT_CONVERGED, "the joint fit did not converge")
    return _summarise(problem, step, lines, options, noise, start / fs)


def _check_lines(lines: Sequence[ProbeLine]) -> None:
    if len(lines) == 0:
        raise ValueError("the joint fit needs at least one probe")
    ids = [line.probe_id for line in lines]
    if len(set(ids)) != len(ids):
        raise ValueError(f"probe ids {ids} repeat: each probe needs its own")
    for line in lines:
        if not (math.isfinite(line.expected_frequency_hz) and line.expected_frequency_hz > 0):
            raise ValueError(
                f"probe {line.probe_id}: expected frequency {line.expected_frequency_hz!r} Hz is not positive"
            )


def _solve(problem: JointProblem, q0: np.ndarray, options: JointOptions, tol_chi2: float) -> JointStep | None:
    """Levenberg–Marquardt on q with the linear parameters projected out; None if it does not
    converge. Converged when the Gauss–Newton step would lower χ² by less than ``tol_chi2``.

    θmax is kept within the one-probe fit's bounds (at θ0 = 0 only κ·θmax is well determined,
    and a weak line's θmax could otherwise run to 0 with its κ to infinity): a θmax at a bound
    that the descent pushes outwards is held there for the step (an active set).
    """
    low, high = np.full(q0.size, -np.inf), np.full(q0.size, np.inf)
    low[AMPLITUDE::P], high[AMPLITUDE::P] = AMPLITUDE_BOUNDS_RAD
    step = project(problem, np.clip(q0, low, high))
    damping = 1e-3
    for _ in range(options.max_iterations):
        jacobian = _projected_jacobian(problem, step)
        gradient = jacobian.T @ (problem.weights[:, None] * step.residual).ravel()
        normal = jacobian.T @ jacobian
        held = ((step.q <= low) & (gradient > 0)) | ((step.q >= high) & (gradient < 0))
        free = np.flatnonzero(~held)
        scale = np.sqrt(np.diag(normal)[free])
        scale[scale == 0] = 1.0
        scaled = normal[np.ix_(free, free)] / np.outer(scale, scale)
        scaled_gradient = gradient[free] / scale
        try:
            predicted = float(scaled_gradient @ np.linalg.solve(scaled, scaled_gradient))
            delta = -np.linalg.solve(scaled + damping * np.eye(free.size), scaled_gradient) / scale
        except np.linalg.LinAlgError:
            return None
        if predicted < tol_chi2:
            return step
        q = step.q.copy()
        q[free] += delta
        trial = project(problem, np.clip(q, low, high))
        if trial.cost < step.cost:
            step, damping = trial, max(damping / 10.0, 1e-9)
        else:
            damping *= 10.0
            if damping > 1e9:
                return None
    return None


def held_at_bound(q: np.ndarray) -> np.ndarray:
    """Mask over all parameters (q, then the linear ones) of the θmax held at a bound: a number
    the data did not give, left out of the Fisher information as the one-probe fit's active set."""
    amplitude = np.abs(q[AMPLITUDE::P])
    held = np.zeros(q.size, bool)
    held[AMPLITUDE::P] = np.isclose(amplitude, AMPLITUDE_BOUNDS_RAD[0], rtol=1e-6) | np.isclose(
        amplitude, AMPLITUDE_BOUNDS_RAD[1], rtol=1e-6
    )
    return held


def _summarise(
    problem: JointProblem,
    step: JointStep,
    lines: Sequence[ProbeLine],
    options: JointOptions,
    noise: np.ndarray,
    start_s: float,
) -> list[RingdownFit]:
    n = problem.y.shape[1]
    fisher = fisher_information(problem, step)
    fitted = ~np.concatenate([held_at_bound(step.q), np.zeros(fisher.shape[0] - step.q.size, bool)])
    fisher_inv = np.full(fisher.shape, np.nan)
    try:
        fisher_inv[np.ix_(fitted, fitted)] = scaled_inverse(fisher[np.ix_(fitted, fitted)])
    except np.linalg.LinAlgError:
        fisher_inv[:] = np.nan
    if not np.all(np.diag(fisher_inv)[fitted] > 0):  # NaN too
        message = "singular Fisher information: the lines are not separable"
        return [failure(FitStatus.NOT_CONVERGED, message, theta0_rad=x.theta0_rad, probe_id=x.probe_id) for x in lines]
    chi2_dof = step.cost / (step.residual.size - int(fitted.sum()))
    if chi2_dof > options.max_chi2_dof:
        message = f"χ²/dof = {chi2_dof:.1f} > {options.max_chi2_dof:g}: the joint model does not describe these data"
        return [
            failure(FitStatus.BAD_FIT, message, theta0_rad=line.theta0_rad, probe_id=line.probe_id) for line in lines
        ]
    covariance = fisher_inv * chi2_dof
    total = float(np.sum((problem.y - problem.y.mean(axis=1, keepdims=True)) ** 2))
    r_squared = 1.0 - float(np.sum(step.residual**2)) / total if total > 0 else math.nan
    fits = []
    for k, line in enumerate(lines):
        fits.append(_probe_fit(k, line, step, covariance, fisher_inv, chi2_dof, r_squared, noise, n, start_s, problem))
    return fits


def _probe_fit(
    k: int,
    line: ProbeLine,
    step: JointStep,
    covariance: np.ndarray,
    fisher_inv: np.ndarray,
    chi2_dof: float,
    r_squared: float,
    noise: np.ndarray,
    n: int,
    start_s: float,
    problem: JointProblem,
) -> RingdownFit:
    k_p, n_lin = problem.probes * P, problem.probes + 1
    # Probe k's own parameters: its q, then its κ and the channel's B_DC, for each channel.
    idx = list(range(P * k, P * (k + 1)))
    for c in range(problem.y.shape[0]):
        idx += [k_p + n_lin * c + k, k_p + n_lin * c + problem.probes]
    own = covariance[np.ix_(idx, idx)]
    f, damping, amplitude, phase = step.q[P * k : P * (k + 1)]
    amplitude_std = math.sqrt(own[AMPLITUDE, AMPLITUDE]) if own[AMPLITUDE, AMPLITUDE] > 0 else math.nan
    undetermined = () if amplitude_std <= AMPLITUDE_LIMIT_RAD else ("amplitude_rad",)
    if math.isnan(amplitude_std):
        message = f"θmax not determined: the fit ran to its bound {math.degrees(amplitude):.1f}°; f is unaffected"
    elif undetermined:
        limit = math.degrees(AMPLITUDE_LIMIT_RAD)
        message = f"θmax not determined: σ {math.degrees(amplitude_std):.2f}° > {limit:.2f}°"
    else:
        message = ""
    kappa = step.coef[:, k]
    signal_power = float(np.mean(kappa**2) * np.var(step.g[k]))
    names = list(NONLINEAR)
    for c in range(problem.y.shape[0]):
        suffix = "" if problem.y.shape[0] == 1 else f"_{c + 1}"
        names += [f"kappa_t{suffix}", f"offset_t{suffix}"]
    fit = RingdownFit(
        status=FitStatus.OK,
        message=message,
        theta0_rad=float(line.theta0_rad),
        frequency_hz=float(f),
        frequency_std_hz=float(math.sqrt(covariance[P * k, P * k])),
        frequency_crb_hz=float(math.sqrt(fisher_inv[P * k, P * k])),
        damping_per_s=float(damping),
        amplitude_rad=math.nan if undetermined else float(amplitude),
        phase_rad=wrapped_rad(phase),
        kappa_t=float(kappa[0]),
        offset_t=float(step.coef[0, -1]),
        chi2_dof=float(chi2_dof),
        r_squared=r_squared,
        snr_db=10.0 * math.log10(signal_power / float(np.mean(noise**2))) if signal_power > 0 else -math.inf,
        noise_std_t=float(noise.mean()),
        n_samples=n,
        duration_s=n * problem.dt,
        start_offset_s=start_s,
        parameter_names=tuple(names),
        covariance=own,
        pickup=tuple(complex(c) for c in problem.pickups[k]),
        undetermined=undetermined,
        probe_id=line.probe_id,
    )
    return _with_swing_from_size(fit, line.pickup_scale_t)


def _with_swing_from_size(fit: RingdownFit, scale_t: float) -> RingdownFit:
    """``fit`` with θmax from its signal's size (:func:`start_swing_rad`) where the pickup's
    absolute scale is known; else ``fit`` as it is. The shape's θmax is not used even where it
    is determined: the magnet swings about its rest angle, which the model leaves out, and the
    pickup's harmonics there pass for a different θmax (tens of percent at 15 mrad), while the
    size is off by only g'(0)/g'(θs), which the sweep's model, knowing θs, takes out
    (:meth:`mows.sweep.decompose.Ringdowns.start_swing_about_rad`)."""
    if not math.isfinite(scale_t):
        return fit
    swing = start_swing_rad(fit, scale_t)
    if not math.isfinite(swing):
        return fit
    if "amplitude_rad" not in fit.undetermined:
        return dataclasses.replace(fit, amplitude_rad=swing)
    message = f"θmax {math.degrees(swing):.2f}° from the signal's size through the pickup's absolute scale"
    return dataclasses.replace(fit, amplitude_rad=swing, undetermined=(), message=message)


SWING_BRACKET_RAD = (1e-4, 0.7)  # within the potential's interval


def start_swing_rad(fit: RingdownFit, scale_t: float) -> float:
    """The swing θmax at the start of a fit's window, from the power of its fitted signal.

    ``scale_t`` times the fit's pickup series (:func:`mows.physics.fluxgate.pickup_scale_t`) is
    the sensors' absolute signal of the swinging magnet in tesla, so the fitted signal's power, ``noise_std_t``² ×
    10^(``snr_db``/10), fixes the swing: the A0 whose ring-down A0·e^(−δt)·cos(2πft) through
    the pickup has that variance over the window. A joint fit may leave θmax itself
    undetermined (its shape barely depends on it), but not its signal's size. NaN if the
    fit's numbers do not fix it."""
    power = fit.noise_std_t**2 * 10.0 ** (fit.snr_db / 10.0)
    if not (math.isfinite(power) and power > 0 and fit.pickup):
        return math.nan
    pickup = scale_t * np.asarray(fit.pickup, complex)
    t = np.linspace(0.0, fit.duration_s, fit.n_samples, endpoint=False)
    carrier = np.exp(-fit.damping_per_s * t) * np.cos(2.0 * math.pi * fit.frequency_hz * t)
    orders = np.arange(pickup.size)

    def excess(swing: float) -> float:
        signal = np.real(np.exp(1j * np.multiply.outer(swing * carrier, orders)) @ pickup)
        return float(np.var(signal)) - power

    low, high = SWING_BRACKET_RAD
    if not excess(low) < 0.0 < excess(high):
        return math.nan
    return float(brentq(excess, low, high, xtol=1e-7))
