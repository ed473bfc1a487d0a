"""Inside one ring-down: where a constant-frequency fit fails, and which effect explains it.

The estimator (:func:`mows.estimate.ringdown.fit_ringdown`) fits one constant f to a ring-down
whose amplitude decays from θmax to θmax·e^(−δT). The probe is not a linear oscillator: its
frequency depends on the amplitude (harmonic balance of the full potential,
:meth:`mows.physics.potential.ArcPotential.frequency_hz`; the field spring m·Bx' is weakened to
m·Bx'·2J1(A)/A ≈ m·Bx'·(1 − A²/8)), so the instantaneous frequency drifts as the amplitude
decays: a chirp.

Method. The fitted window is cut into consecutive pieces of ``piece_periods`` periods, each fitted
with the same signal model (f_i ± σ_i, δ_i). A window of several probes (a multi-tone
excitation's, docs/multi_probe.md) is fitted jointly, over the whole window and over each piece
(:func:`mows.estimate.ringdown.fit_ringdowns`, each probe at its own θ0), the pieces as long as
``piece_periods`` periods of the slowest probe, and each probe is diagnosed from its own fits;
one probe is a window of one line. Piece i starts at the amplitude
A_i = A_0·e^(−δ·t_i), A_0 the whole-window fit's θmax where it determined it, else the stop
less its rest offset (:func:`mows.physics.ringdown_average.swing_from_stop_rad`), and the
potential predicts its frequency as the estimator would read it, Σ_q c_q·f(A_q) over the piece's amplitude nodes
(:func:`mows.physics.ringdown_average.amplitude_nodes`). The potential is that of the paper's
Eq. 6 field along the axis Bx', taken from the ring-down's own frequency: Eq. 6 inverted
(:func:`mows.estimate.axis.estimate_along_axis`), then corrected once so that the potential's
window-averaged frequency at the fitted amplitude equals the fitted f (the finite amplitude
itself lowers f by ≈ β0·Bx'·⟨A²⟩/8).

Tests on the pieces, each against its own uncertainties:

- **constant frequency**: χ² of f_i about their weighted mean (dof = pieces − 1);
- **chirp size**: f_i = c + λ·p_i with p_i the predicted piece frequencies: λ = 1 is the finite
  amplitude as predicted, λ = 0 no chirp; and the measured slope df/d(A²) beside the predicted;
- **amplitude-dependent damping**: the slope of δ_i against A_i.

The verdict names ``finite_amplitude`` when a chirp is detected (constant frequency rejected
at p < ``ALPHA``, or |λ| > 3σ) and λ is within 3σ of 1; ``unexplained_chirp`` (another
amplitude-dependent spring: a gradient along the lever, gravity, curvature, a nonlinear spring)
when it is detected and λ is not; ``amplitude_dependent_damping`` when only the damping moves;
``constant`` when nothing is detected, with the predicted chirp's size against the pieces' σ.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Sequence

import numpy as np
from scipy import stats

from mows.estimate.axis import estimate_along_axis
from mows.estimate.probe_set import window_probes
from mows.estimate.ringdown import FitOptions, ProbeLine, RingdownFit, fit_ringdowns, usable_window
from mows.estimate.segments import Segment, gap_message
from mows.estimate.stream import FitSettings
from mows.physics import ringdown_average
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe

ALPHA = 1e-3  # significance level of each test
SIGMAS = 3.0  # a slope or λ this many σ from a value is "different"
PIECE_PERIODS = 10.0


class ChirpVerdict(enum.StrEnum):
    """What the tests on the pieces found (module docstring)."""

    FINITE_AMPLITUDE = "finite_amplitude"
    UNEXPLAINED_CHIRP = "unexplained_chirp"
    AMPLITUDE_DEPENDENT_DAMPING = "amplitude_dependent_damping"
    CONSTANT = "constant"


@dataclasses.dataclass(frozen=True)
class Piece:
    """One piece of the window: start time after the first fitted sample, its start amplitude
    (from the whole fit), its fit (f, σ_f, δ), and the frequency the finite amplitude predicts."""

    t_s: float
    amplitude_rad: float
    frequency_hz: float
    frequency_std_hz: float
    damping_per_s: float
    damping_std_per_s: float
    predicted_hz: float


@dataclasses.dataclass(frozen=True)
class ChirpDiagnosis:
    """Where a constant-frequency fit fails inside one ring-down and what explains it."""

    fit: RingdownFit
    pieces: tuple[Piece, ...]
    field_along_axis_t: float
    constant_chi2_dof: float
    constant_p_value: float
    chirp_ratio: float  # λ: the measured chirp over the predicted one
    chirp_ratio_std: float
    slope_hz_per_rad2: float  # df/d(A²), measured
    slope_std_hz_per_rad2: float
    predicted_slope_hz_per_rad2: float
    damping_slope_per_s_per_rad: float
    damping_slope_std_per_s_per_rad: float
    verdict: ChirpVerdict
    explanation: str


# ChirpDiagnosis's fields that the tests on the pieces fill, in order.
TEST_FIELDS = tuple(f.name for f in dataclasses.fields(ChirpDiagnosis))[3:-2]


class ChirpError(ValueError):
    """A ring-down whose chirp cannot be measured (failed fit, too short, no amplitude)."""


def diagnose_ringdown(
    samples: np.ndarray,
    sample_rate_hz: float,
    lines: Sequence[ProbeLine],
    probes: Sequence[Probe],
    options: FitOptions,
    f00_hz: Sequence[float],
    saturated: np.ndarray | None = None,
    coil_off_skip_s: float = 0.0,
    piece_periods: float = PIECE_PERIODS,
) -> list[ChirpDiagnosis | ChirpError]:
    """The chirp diagnosis (module docstring) of each probe ringing in one window: ``lines[k]``
    (:class:`mows.estimate.ringdown.ProbeLine`) of the probe of constants ``probes[k]`` and
    zero-field frequency ``f00_hz[k]``, all fitted jointly over the window and over each piece
    (:func:`mows.estimate.ringdown.fit_ringdowns`; one probe is a window of one line). Lines
    beyond those of ``probes`` are of probes rung in the window but not diagnosed: fitted
    beside the others, not reported. The pieces are ``piece_periods`` periods of the slowest
    line they fit long. In the order of ``probes``, a :class:`ChirpError` in place of a probe's
    diagnosis when its whole-window fit fails, the window holds fewer than three pieces, or the
    probe has no amplitude or fewer than three fitted pieces."""
    samples = np.asarray(samples, float)
    mask = np.zeros(samples.shape, bool) if saturated is None else np.asarray(saturated, bool)
    try:
        fits = fit_ringdowns(samples, sample_rate_hz, lines, mask, options, coil_off_skip_s)
    except ValueError as error:  # e.g. a window announced at no frequency
        return [ChirpError(f"no fit: {error}") for _ in lines]
    found: list[ChirpDiagnosis | ChirpError] = [
        ChirpError(f"the whole-window fit failed: {fit.report()}") for fit in fits[: len(probes)]
    ]
    ok = [k for k, fit in enumerate(fits[: len(probes)]) if fit.ok]
    if not ok:
        return found
    piece_lines = [
        dataclasses.replace(line, expected_frequency_hz=fit.frequency_hz) if fit.ok else line
        for line, fit in zip(lines, fits)
    ]
    start, stop = usable_window(mask, int(round(coil_off_skip_s * sample_rate_hz)))
    # Every line is fitted in each piece, so each piece holds piece_periods of the slowest.
    length = int(round(piece_periods * sample_rate_hz / min(line.expected_frequency_hz for line in piece_lines)))
    count = (stop - start) // length
    if count < 3:
        short = ChirpError(f"{fits[ok[0]].duration_s:.3f} s hold {count} pieces of {piece_periods:g} periods; need 3")
        return [found[k] if k not in ok else short for k in range(len(found))]
    piece_options = dataclasses.replace(options, min_periods=0.8 * piece_periods)  # f may sit above the whole f
    piece_fits = [
        fit_ringdowns(
            samples[start + i * length : start + (i + 1) * length], sample_rate_hz, piece_lines, None, piece_options
        )
        for i in range(count)
    ]
    for k in ok:
        try:
            found[k] = _probe_diagnosis(
                fits[k], [p[k] for p in piece_fits], probes[k], f00_hz[k], length, sample_rate_hz
            )
        except ChirpError as error:
            found[k] = error
    return found


def diagnose_segment(
    segment: Segment, settings: FitSettings, piece_periods: float = PIECE_PERIODS
) -> list[tuple[int, ChirpDiagnosis | ChirpError]]:
    """(probe id, diagnosis) of each probe in a recorded window, fitted as the estimator fits it
    with ``settings`` (:meth:`mows.estimate.stream.FitSettings.window_fits`): every probe the
    window holds, each at its own θ0 and tone (a probe the set does not list, or a window with
    missing samples: a ChirpError saying why)."""
    window = segment.window
    held = window_probes(settings.probes, window)
    if segment.missing_samples:
        return [(p.probe_id, ChirpError(gap_message(segment))) for p in held]
    known = [p for p in held if p.entry is not None]
    found: dict[int, ChirpDiagnosis | ChirpError] = {
        p.probe_id: ChirpError(p.unknown_message(settings.probes)) for p in held if p.entry is None
    }
    try:
        lines = settings.lines(known) if known else []
    except ValueError as error:
        found |= {p.probe_id: ChirpError(f"cannot build the signal model: {error}") for p in known}
    else:
        entries = [p.entry for p in known if p.entry is not None]
        probes, f00s = [e.probe for e in entries], [e.f00_hz for e in entries]
        if lines:
            diagnoses = diagnose_ringdown(
                segment.samples_t,
                segment.sample_rate_hz,
                lines + settings.unlisted_lines(held),
                probes,
                settings.options,
                f00s,
                saturated=segment.saturated,
                coil_off_skip_s=settings.coil_off_skip_s,
                piece_periods=piece_periods,
            )
            found |= dict(zip((p.probe_id for p in known), diagnoses))
    return [(p.probe_id, found[p.probe_id]) for p in held]


def _probe_diagnosis(
    fit: RingdownFit, piece_fits: Sequence[RingdownFit], probe: Probe, f00_hz: float, length: int, sample_rate_hz: float
) -> ChirpDiagnosis:
    """One probe's diagnosis from its whole-window fit and its fit in each piece of ``length`` samples."""
    start_amplitude = _start_amplitude_rad(fit, probe)
    if not math.isfinite(start_amplitude):
        raise ChirpError("the rest offset lies beyond the stop: the chirp cannot be put against amplitude")
    field = _field_along_axis(fit, probe, f00_hz, start_amplitude)
    pieces: list[Piece] = []
    for i, piece in enumerate(piece_fits):
        if not piece.ok:
            continue
        t = (i * length) / sample_rate_hz
        amplitude = start_amplitude * math.exp(-fit.damping_per_s * t)
        predicted = _predicted_hz(probe, field, fit, amplitude, length / sample_rate_hz)
        damping_std = math.sqrt(piece.covariance[1, 1])
        pieces.append(
            Piece(t, amplitude, piece.frequency_hz, piece.frequency_std_hz, piece.damping_per_s, damping_std, predicted)
        )
    if len(pieces) < 3:
        failed = next(piece.message for piece in piece_fits if not piece.ok)
        raise ChirpError(f"only {len(pieces)} of {len(piece_fits)} pieces could be fitted ({failed}); need 3")
    return _diagnosis(fit, tuple(pieces), field)


def _start_amplitude_rad(fit: RingdownFit, probe: Probe) -> float:
    """The swing at the first fitted sample: the fit's θmax where it determined it, else the
    probe's stop less the fit's rest offset (0 where not determined: the model here has the
    field along the axis only), decayed from the switch-off
    (:func:`mows.physics.ringdown_average.swing_from_stop_rad`); NaN where the offset passes the stop."""
    if math.isfinite(fit.amplitude_rad):
        return fit.amplitude_rad
    rest, since_release = np.nan_to_num(fit.rest_offset_rad), fit.start_offset_s
    return float(ringdown_average.swing_from_stop_rad(probe.theta_stop_rad, rest, fit.damping_per_s, since_release))


def _field_along_axis(fit: RingdownFit, probe: Probe, f00_hz: float, amplitude_rad: float) -> float:
    """Bx' that makes the potential's window-averaged frequency at the start amplitude equal the
    fitted f: Eq. 6 inverted, then one correction for the finite amplitude's own shift."""
    field = estimate_along_axis(fit, probe, f00_hz).field_along_axis_t
    small = _predicted_hz(probe, field, fit, 0.0, fit.duration_s) - f00_hz
    averaged = _predicted_hz(probe, field, fit, amplitude_rad, fit.duration_s)
    return field * small / (averaged - f00_hz) if averaged != f00_hz else field


def _predicted_hz(probe: Probe, field_t: float, fit: RingdownFit, amplitude_rad: float, duration_s: float) -> float:
    """The frequency a constant-frequency fit with ``fit``'s signal model and damping reads over
    a window starting at ``amplitude_rad``."""
    if amplitude_rad == 0.0:
        nodes, weights = np.zeros((1, 1)), np.ones((1, 1))
    else:
        nodes, weights = ringdown_average.amplitude_nodes(
            fit.theta0_rad, amplitude_rad, fit.damping_per_s, duration_s, pickup=np.asarray(fit.pickup)
        )
    potential = ArcPotential.from_local_field(probe, np.tile([field_t, 0.0, 0.0], (nodes.shape[1], 1)))
    return float(weights[0] @ potential.frequency_hz(nodes[0]))


def _weighted_line(x: np.ndarray, y: np.ndarray, std: np.ndarray) -> tuple[float, float]:
    """(slope, σ_slope) of y = a + b·x with weights 1/σ²."""
    w = 1.0 / np.asarray(std) ** 2
    xm = (w @ x) / w.sum()
    sxx = w @ (x - xm) ** 2
    return float((w @ ((x - xm) * y)) / sxx), float(1.0 / math.sqrt(sxx))


def _diagnosis(fit: RingdownFit, pieces: tuple[Piece, ...], field: float) -> ChirpDiagnosis:
    f = np.array([p.frequency_hz for p in pieces])
    std = np.array([p.frequency_std_hz for p in pieces])
    amplitude2 = np.array([p.amplitude_rad for p in pieces]) ** 2
    predicted = np.array([p.predicted_hz for p in pieces])
    w = 1.0 / std**2
    constant_chi2 = float(w @ (f - (w @ f) / w.sum()) ** 2)
    dof = len(pieces) - 1
    constant_p = float(stats.chi2.sf(constant_chi2, dof))
    ratio, ratio_std = _weighted_line(predicted, f, std) if np.ptp(predicted) > 0 else (math.nan, math.inf)
    slope, slope_std = _weighted_line(amplitude2, f, std)
    predicted_slope, _ = _weighted_line(amplitude2, predicted, std)
    damping_std = np.array([p.damping_std_per_s for p in pieces])
    damping_slope, damping_slope_std = _weighted_line(
        np.sqrt(amplitude2), np.array([p.damping_per_s for p in pieces]), damping_std
    )
    values = (constant_chi2 / dof, constant_p, ratio, ratio_std, slope, slope_std, predicted_slope)
    numbers = dict(zip(TEST_FIELDS, values + (damping_slope, damping_slope_std)))
    verdict, explanation = _verdict(numbers, std, predicted)
    return ChirpDiagnosis(fit, pieces, field, **numbers, verdict=verdict, explanation=explanation)


def _verdict(numbers: dict[str, float], std: np.ndarray, predicted: np.ndarray) -> tuple[ChirpVerdict, str]:
    """(verdict, explanation) from the tests' numbers (module docstring)."""
    slope, slope_std = numbers["slope_hz_per_rad2"], numbers["slope_std_hz_per_rad2"]
    ratio, ratio_std = numbers["chirp_ratio"], numbers["chirp_ratio_std"]
    damping, damping_std = numbers["damping_slope_per_s_per_rad"], numbers["damping_slope_std_per_s_per_rad"]
    predicted_slope = numbers["predicted_slope_hz_per_rad2"]
    chirp = numbers["constant_p_value"] < ALPHA or abs(slope) > SIGMAS * slope_std
    sizes = (
        f"measured df/d(A²) = {slope * 1e3:.3g} ± {slope_std * 1e3:.2g} mHz/rad², the finite amplitude predicts "
        f"{predicted_slope * 1e3:.3g} mHz/rad² (λ = {ratio:.3g} ± {ratio_std:.2g})"
    )
    if chirp and abs(ratio - 1.0) <= SIGMAS * ratio_std:
        return ChirpVerdict.FINITE_AMPLITUDE, (
            f"the frequency chirps with the decaying amplitude as the potential predicts: {sizes}; a constant-"
            "frequency fit reports the kernel-weighted average (mows.physics.ringdown_average), which the lab's "
            "finite_amplitude effect models"
        )
    if chirp:
        return ChirpVerdict.UNEXPLAINED_CHIRP, (
            f"the frequency chirps, but not by the size the finite amplitude predicts: {sizes}; another "
            "amplitude-dependent spring (a gradient along the lever, gravity in the plane, field curvature, a "
            "nonlinear spring) or a wrong θmax"
        )
    if abs(damping) > SIGMAS * damping_std:
        return ChirpVerdict.AMPLITUDE_DEPENDENT_DAMPING, (
            f"the damping changes with amplitude: dδ/dA = {damping:.3g} ± {damping_std:.2g} 1/(s·rad) (air drag ∝ "
            f"velocity² or stop contact); the frequency does not chirp ({sizes})"
        )
    span = float(np.ptp(predicted))
    return ChirpVerdict.CONSTANT, (
        f"a constant frequency describes every piece (no chirp detected: {sizes}); the finite amplitude's chirp over "
        f"the window, {span * 1e3:.3g} mHz, is {span / float(np.median(std)):.2g} × a piece's σ"
    )
