"""Estimator benchmark: precision against the Cramér–Rao bound, and speed against curve_fit.

Synthetic ring-downs follow the fit model exactly (Eqs. S2, S12) with white Gaussian noise,
so the only question is how close the estimator comes to the bound. The signal-to-noise
ratio is defined once, for every orientation, by the strength of the probe's signal:

    SNR = (κ·sin θmax)² / (2σ²),

the power of the ring-down's first harmonic at θ0 = 0 over the noise power per sample. Near
θ0 = 90° the signal is mostly at 2f and far weaker, so the bound there is much larger at the
same SNR (Eq. 3 and docs/physics.md §3).
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np
from scipy.optimize import curve_fit

from mows.estimate import ringdown
from mows.estimate.ringdown import problem
from mows.physics.signal import signal_t

SAMPLE_RATE_HZ = 20_000.0
N_SAMPLES = 10_000  # 0.5 s, as the paper evaluates
FREQUENCY_HZ = 112.6
DAMPING_PER_S = 1.8
AMPLITUDE_RAD = math.radians(20.0)
PHASE_RAD = 0.7
KAPPA_T = 1.2e-7
OFFSET_T = 3e-9


def reference_crb_hz(theta0_rad: float, noise_std_t: float, **options) -> float:
    """The Cramér–Rao bound of f for the ring-down of the constants above at θ0 in white noise σ
    (``options``: those of :func:`mows.estimate.ringdown.problem.cramer_rao_frequency_hz`)."""
    return problem.cramer_rao_frequency_hz(
        N_SAMPLES,
        SAMPLE_RATE_HZ,
        FREQUENCY_HZ,
        DAMPING_PER_S,
        AMPLITUDE_RAD,
        PHASE_RAD,
        theta0_rad,
        KAPPA_T,
        noise_std_t,
        **options,
    )


@dataclasses.dataclass(frozen=True)
class RingdownCase:
    theta0_rad: float
    snr_db: float

    @property
    def noise_std_t(self) -> float:
        return KAPPA_T * math.sin(AMPLITUDE_RAD) / math.sqrt(2.0) / 10 ** (self.snr_db / 20.0)

    def clean_t(self) -> np.ndarray:
        t = np.arange(N_SAMPLES) / SAMPLE_RATE_HZ
        return signal_t(
            t, self.theta0_rad, AMPLITUDE_RAD, FREQUENCY_HZ, PHASE_RAD, DAMPING_PER_S, KAPPA_T, offset_t=OFFSET_T
        )

    def draw(self, rng: np.random.Generator, clean=None) -> np.ndarray:
        clean = self.clean_t() if clean is None else clean
        return clean + self.noise_std_t * rng.standard_normal(N_SAMPLES)

    def crb_hz(self) -> float:
        return reference_crb_hz(self.theta0_rad, self.noise_std_t)

    def fit(self, samples) -> ringdown.RingdownFit:
        # The driver excites near resonance, so the expected frequency is close but not exact.
        return ringdown.fit_ringdown(samples, SAMPLE_RATE_HZ, self.theta0_rad, FREQUENCY_HZ * 0.995)


@dataclasses.dataclass
class PrecisionCell:
    """Monte Carlo figures of one (θ0, SNR) cell; errors are f̂ − f in units of the CRB."""

    theta0_deg: float
    snr_db: float
    crb_hz: float
    errors_hz: np.ndarray
    reported_std_hz: np.ndarray
    failures: int

    @property
    def efficiency(self) -> float:
        """(CRB/σ_MC)²: 1 for an efficient estimator."""
        return float((self.crb_hz / self.errors_hz.std(ddof=1)) ** 2)

    @property
    def std_over_crb(self) -> float:
        return float(self.errors_hz.std(ddof=1) / self.crb_hz)

    @property
    def bias_sigma(self) -> float:
        return float(self.errors_hz.mean() / self.errors_hz.std(ddof=1))

    @property
    def pull_width(self) -> float:
        return float(np.std(self.errors_hz / self.reported_std_hz, ddof=1))


def precision_cell(theta0_deg: float, snr_db: float, trials: int, rng: np.random.Generator) -> PrecisionCell:
    case = RingdownCase(math.radians(theta0_deg), snr_db)
    clean = case.clean_t()
    errors, stds, failures = [], [], 0
    for _ in range(trials):
        fit = case.fit(case.draw(rng, clean))
        if not fit.ok:
            failures += 1
            continue
        errors.append(fit.frequency_hz - FREQUENCY_HZ)
        stds.append(fit.frequency_std_hz)
    return PrecisionCell(theta0_deg, snr_db, case.crb_hz(), np.array(errors), np.array(stds), failures)


def _curve_fit_once(case: RingdownCase, samples: np.ndarray):
    """The same data fitted with scipy.optimize.curve_fit on the full-rate model (the rest
    offset ε included), from the same start our estimator's spectral stage finds (so only the
    optimiser differs)."""
    t = np.arange(N_SAMPLES) / SAMPLE_RATE_HZ
    start = ringdown.starting_point(samples, SAMPLE_RATE_HZ, case.theta0_rad, FREQUENCY_HZ * 0.995)

    def model(tt, f, delta, amp, phi, rest_offset, kappa, offset):
        return signal_t(tt, case.theta0_rad + rest_offset, amp, f, phi, delta, kappa, offset_t=offset)

    p, _ = curve_fit(model, t, samples, p0=start, method="lm", xtol=1e-12, ftol=1e-12, maxfev=20_000)
    return p[0]


def speed(
    theta0_deg: float = 30.0, snr_db: float = 40.0, trials: int = 100, baseline_trials: int = 20, rng=None
) -> dict:
    """Median wall time of one fit (0.5 s, 20 kS/s) and of curve_fit on the same data."""
    rng = np.random.default_rng(1) if rng is None else rng
    case = RingdownCase(math.radians(theta0_deg), snr_db)
    clean = case.clean_t()
    data = [case.draw(rng, clean) for _ in range(trials)]
    ours, ours_err = [], []
    for samples in data:
        t0 = time.perf_counter()
        fit = case.fit(samples)
        ours.append(time.perf_counter() - t0)
        ours_err.append(fit.frequency_hz - FREQUENCY_HZ)
    theirs, theirs_err = [], []
    for samples in data[:baseline_trials]:
        t0 = time.perf_counter()
        f = _curve_fit_once(case, samples)
        theirs.append(time.perf_counter() - t0)
        theirs_err.append(f - FREQUENCY_HZ)
    fit_ms = 1e3 * float(np.median(ours))
    curve_fit_ms = 1e3 * float(np.median(theirs))
    paired = np.array(ours_err[:baseline_trials]) - np.array(theirs_err)
    return {
        "fit_ms_median": fit_ms,
        "curve_fit_ms_median": curve_fit_ms,
        "speedup": curve_fit_ms / fit_ms,
        "fit_std_over_crb": float(np.std(ours_err, ddof=1) / case.crb_hz()),
        "curve_fit_std_over_crb": float(np.std(theirs_err, ddof=1) / case.crb_hz()),
        "max_difference_to_curve_fit_sigma": float(np.max(np.abs(paired)) / case.crb_hz()),
    }


def precision_grid(snrs_db=(20.0, 40.0, 60.0), step_deg: float = 15.0, trials: int = 200, rng=None):
    rng = np.random.default_rng(2) if rng is None else rng
    return [precision_cell(theta0, snr, trials, rng) for snr in snrs_db for theta0 in np.arange(0.0, 360.0, step_deg)]


def run(trials: int = 200, step_deg: float = 15.0, speed_trials: int = 100, baseline_trials: int = 20) -> dict:
    """Figures for `mows bench`: speed against curve_fit (``speed_trials`` fits, ``baseline_trials``
    of curve_fit), and precision over the θ0 × SNR grid (θ0 every ``step_deg``, ``trials`` per
    cell) in cells where the bound is below 5 mHz."""
    figures = speed(trials=speed_trials, baseline_trials=baseline_trials)
    cells = precision_grid(step_deg=step_deg, trials=trials)
    bounded = [c for c in cells if c.crb_hz < 5e-3]
    figures.update(
        {
            "efficiency_min": min(c.efficiency for c in bounded),
            "std_over_crb_max": max(c.std_over_crb for c in bounded),
            "bias_max_sigma": max(abs(c.bias_sigma) for c in bounded),
            "pull_width_near_90deg": [c.pull_width for c in cells if c.theta0_deg % 180 == 90],
            "cells": len(cells),
            "cells_with_crb_below_5mhz": len(bounded),
            "trials_per_cell": trials,
            "monte_carlo_std_error_of_std_ratio": 1.0 / math.sqrt(2 * trials),
        }
    )
    return figures
