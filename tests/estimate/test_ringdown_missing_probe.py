"""A probe of a group that does not ring (no magnet, its excitation refused) is reported as
such, never with numbers of a neighbour's line; the probes that ring keep their fits.

Three probes at 0°, 30° and 60° (as in tests/estimate/test_ringdown_joint.py), their lines
10 Hz apart and 2 Hz apart (the window's resolution), one of them left out of the signal.
Every OK number is compared with the truth the signal was made from.
"""

import math

import numpy as np
import pytest

from mows.bench.estimator import N_SAMPLES, SAMPLE_RATE_HZ
from mows.estimate.ringdown import ProbeLine, fit_ringdowns
from mows.estimate.ringdown.types import FitStatus
from mows.physics.signal import signal_t

SIGMA_T = 3e-10
SEEDS = range(4)


def scene(separation_hz: float) -> list[tuple[float, float, float, float, float, float]]:
    """f, δ, θmax, φ, κ, θ0 of each probe."""
    return [
        (112.6 - separation_hz, 1.7, math.radians(20.0), 0.3, 1.0e-7, 0.0),
        (112.6, 1.8, math.radians(18.0), 2.0, 1.2e-7, math.radians(30.0)),
        (112.6 + separation_hz, 1.9, math.radians(22.0), -1.0, 0.6e-7, math.radians(60.0)),
    ]


def window_t(truth: list, ringing: list[int], seed: int) -> np.ndarray:
    t = np.arange(N_SAMPLES) / SAMPLE_RATE_HZ
    clean = sum(signal_t(t, th, a, f, ph, d, k) for i, (f, d, a, ph, k, th) in enumerate(truth) if i in ringing)
    return clean + SIGMA_T * np.random.default_rng(seed).standard_normal(N_SAMPLES)


def lines_of(truth: list) -> list[ProbeLine]:
    return [ProbeLine(i, row[5], round(row[0])) for i, row in enumerate(truth)]


@pytest.mark.parametrize("missing", [0, 1, 2])
def test_a_probe_that_does_not_ring_10_hz_from_its_neighbours_is_no_oscillation(missing):
    truth, lines = scene(10.0), lines_of(scene(10.0))
    ringing = [i for i in range(3) if i != missing]
    for seed in SEEDS:
        samples = window_t(truth, ringing, seed)
        fits = fit_ringdowns(samples, SAMPLE_RATE_HZ, lines)
        absent = fits[missing]
        assert absent.status == FitStatus.NO_OSCILLATION and math.isnan(absent.frequency_hz), (seed, absent)
        assert f"no line of probe {missing}" in absent.message
        # The others as fitted without the absent probe's line, and at the truth.
        alone = fit_ringdowns(samples, SAMPLE_RATE_HZ, [lines[i] for i in ringing])
        for i, reference in zip(ringing, alone):
            fit = fits[i]
            assert fit.ok and fit.probe_id == i, (seed, fit)
            assert abs(fit.frequency_hz - reference.frequency_hz) <= reference.frequency_std_hz, (seed, i)
            assert abs(fit.frequency_hz - truth[i][0]) < 5 * fit.frequency_std_hz, (seed, i)


def test_a_probe_that_does_not_ring_2_hz_from_its_neighbours_never_gets_numbers():
    # At the window's resolution the fit may lose a ringing neighbour too; it never reports a
    # number for the absent probe, and every number it reports is the truth's.
    truth, lines = scene(2.0), lines_of(scene(2.0))
    for missing in range(3):
        for seed in SEEDS:
            fits = fit_ringdowns(window_t(truth, [i for i in range(3) if i != missing], seed), SAMPLE_RATE_HZ, lines)
            assert not fits[missing].ok, (missing, seed, fits[missing])
            for i, fit in enumerate(fits):
                if fit.ok:
                    assert abs(fit.frequency_hz - truth[i][0]) < 5 * fit.frequency_std_hz, (missing, seed, i)


@pytest.mark.parametrize("separation_hz", [10.0, 2.0])
def test_all_probes_ringing_are_all_ok(separation_hz):
    truth = scene(separation_hz)
    for seed in SEEDS:
        fits = fit_ringdowns(window_t(truth, [0, 1, 2], seed), SAMPLE_RATE_HZ, lines_of(truth))
        assert [fit.status for fit in fits] == [FitStatus.OK] * 3, (seed, [fit.message for fit in fits])
