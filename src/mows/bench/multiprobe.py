"""Two probes in one ring-down: the joint fit's precision against the bound as their lines approach.

Synthetic windows hold two ring-downs of the fit model (Eqs. S2, S12, the probes at θ0 = 0)
10 Hz apart or closer, in white Gaussian noise; the first probe is the estimator bench's
(:mod:`mows.bench.estimator`: 112.6 Hz, 20°, SNR 40 dB), the second has its κ times the
amplitude ratio. For each separation and ratio: each probe's Cramér–Rao bound in the
presence of the other over its bound alone (what the neighbour costs in principle), and the
Monte Carlo error of :func:`mows.estimate.ringdown.fit_ringdowns` over its bound
(what the estimator loses on top), with its bias in units of its scatter.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from mows.bench.estimator import (
    AMPLITUDE_RAD,
    DAMPING_PER_S,
    FREQUENCY_HZ,
    KAPPA_T,
    N_SAMPLES,
    OFFSET_T,
    PHASE_RAD,
    SAMPLE_RATE_HZ,
    RingdownCase,
)
from mows.estimate.ringdown import ProbeLine, cramer_rao_frequency_hz, cramer_rao_hz, fit_ringdowns
from mows.physics.signal import signal_t

SNR_DB = 40.0
SEPARATIONS_HZ = (2.0, 3.0, 5.0, 10.0, 20.0)
RATIOS = (1.0, 0.25)
# The neighbour decays a little faster and starts at another phase: nothing lines up by chance.
NEIGHBOUR_DAMPING_PER_S = 1.9
NEIGHBOUR_PHASE_RAD = -1.3
# The driver excites near resonance: the expected frequencies are close, not exact.
EXPECTED_ERROR = (0.995, 1.004)


@dataclasses.dataclass(frozen=True)
class PairCase:
    separation_hz: float
    ratio: float
    snr_db: float = SNR_DB

    @property
    def noise_std_t(self) -> float:
        return RingdownCase(0.0, self.snr_db).noise_std_t

    def truth(self) -> list[tuple[float, float, float, float, float]]:
        """(f, δ, θmax, φ, κ) of each probe."""
        return [
            (FREQUENCY_HZ, DAMPING_PER_S, AMPLITUDE_RAD, PHASE_RAD, KAPPA_T),
            (
                FREQUENCY_HZ + self.separation_hz,
                NEIGHBOUR_DAMPING_PER_S,
                AMPLITUDE_RAD,
                NEIGHBOUR_PHASE_RAD,
                KAPPA_T * self.ratio,
            ),
        ]

    def lines(self) -> list[ProbeLine]:
        return [
            ProbeLine(probe_id=k, theta0_rad=0.0, expected_frequency_hz=truth[0] * error)
            for k, (truth, error) in enumerate(zip(self.truth(), EXPECTED_ERROR))
        ]

    def clean_t(self) -> np.ndarray:
        t = np.arange(N_SAMPLES) / SAMPLE_RATE_HZ
        lines = [
            signal_t(t, 0.0, amplitude, f, phase, damping, kappa)
            for f, damping, amplitude, phase, kappa in self.truth()
        ]
        return OFFSET_T + np.sum(lines, axis=0)

    def crb_hz(self) -> np.ndarray:
        """Each probe's bound in the presence of the other."""
        return cramer_rao_hz(N_SAMPLES, SAMPLE_RATE_HZ, self.lines(), self.truth(), self.noise_std_t)

    def alone_crb_hz(self) -> np.ndarray:
        """Each probe's bound were it alone (the one-probe bound, without a rest offset)."""
        return np.array(
            [
                cramer_rao_frequency_hz(
                    N_SAMPLES, SAMPLE_RATE_HZ, f, d, a, p, 0.0, k, self.noise_std_t, offset_free=False
                )
                for f, d, a, p, k in self.truth()
            ]
        )


@dataclasses.dataclass
class PairCell:
    """Monte Carlo figures of one case; errors are f̂ − f, (trials, 2), of the converged fits."""

    case: PairCase
    crb_hz: np.ndarray
    alone_crb_hz: np.ndarray
    errors_hz: np.ndarray
    reported_std_hz: np.ndarray
    failures: int
    fit_s: float

    @property
    def std_over_crb(self) -> np.ndarray:
        return self.errors_hz.std(axis=0, ddof=1) / self.crb_hz

    @property
    def bias_sigma(self) -> np.ndarray:
        return self.errors_hz.mean(axis=0) / self.errors_hz.std(axis=0, ddof=1)


def pair_cell(separation_hz: float, ratio: float, trials: int, rng: np.random.Generator) -> PairCell:
    case = PairCase(separation_hz, ratio)
    clean, truth, lines = case.clean_t(), case.truth(), case.lines()
    errors, stds, failures = [], [], 0
    start = time.perf_counter()
    for _ in range(trials):
        fits = fit_ringdowns(clean + case.noise_std_t * rng.standard_normal(N_SAMPLES), SAMPLE_RATE_HZ, lines)
        if not all(fit.ok for fit in fits):
            failures += 1
            continue
        errors.append([fit.frequency_hz - t[0] for fit, t in zip(fits, truth)])
        stds.append([fit.frequency_std_hz for fit in fits])
    fit_s = (time.perf_counter() - start) / max(trials, 1)
    return PairCell(case, case.crb_hz(), case.alone_crb_hz(), np.array(errors), np.array(stds), failures, fit_s)


def run(
    trials: int = 100, separations_hz: tuple = SEPARATIONS_HZ, ratios: tuple = RATIOS, seed: int = 20261125
) -> dict:
    """Figures per separation, ratio and probe (``sep_10hz_ratio_0.25_probe1_std_over_crb``):
    crb_over_alone, std_over_crb, bias_sigma; worst_std_over_crb_10hz (the worst probe at
    10 Hz and above), failures, fit_ms_median (over the cells, the mean time of one joint fit);
    single_fit_ms_median, the one-probe
    fit of one probe alone timed in the same run, and joint_over_single."""
    rng = np.random.default_rng(seed)
    figures: dict[str, object] = {"trials": trials, "snr_db": SNR_DB}
    times, failures, worst = [], 0, math.nan
    for separation in separations_hz:
        for ratio in ratios:
            cell = pair_cell(separation, ratio, trials, rng)
            times.append(cell.fit_s)
            failures += cell.failures
            for probe in range(2):
                key = f"sep_{separation:g}hz_ratio_{ratio:g}_probe{probe}"
                figures[f"{key}_crb_over_alone"] = float(cell.crb_hz[probe] / cell.alone_crb_hz[probe])
                figures[f"{key}_std_over_crb"] = float(cell.std_over_crb[probe])
                figures[f"{key}_bias_sigma"] = float(cell.bias_sigma[probe])
            if separation >= 10.0:
                worst = float(np.fmax(worst, cell.std_over_crb.max()))
    figures["worst_std_over_crb_10hz"] = worst
    figures["failures"] = failures
    joint_ms = 1e3 * float(np.median(times)) if times else math.nan
    single_ms = 1e3 * _single_fit_s(trials, rng)
    figures.update(fit_ms_median=joint_ms, single_fit_ms_median=single_ms, joint_over_single=joint_ms / single_ms)
    return figures


def _single_fit_s(trials: int, rng: np.random.Generator) -> float:
    """Median time of the one-probe fit of the first probe alone, in the same run: the baseline."""
    case = RingdownCase(0.0, SNR_DB)
    clean, times = case.clean_t(), []
    for _ in range(trials):
        samples = case.draw(rng, clean)
        start = time.perf_counter()
        case.fit(samples)
        times.append(time.perf_counter() - start)
    return float(np.median(times))
