"""The calibration bench (scenario ``calibration``) as a stand-in driver sees it: the fits of a
cycle are the bench probe's exact frequency in the environment plus the supply's field at the
present current, with noise. Shared by the calibrator's core and node tests."""

import math

import numpy as np

from mows.estimate.ringdown import COIL_OFF_SKIP_S
from mows.lab.data.synthetic import true_frequency_hz
from mows.physics.field import SumSource
from mows.sim.scenario import load_scenario

BENCH = load_scenario("calibration")
STD_HZ = 3e-4


def bench_fits(current_a: float, theta0_rad: float, repeats: int, rng: np.random.Generator) -> list[dict]:
    """The fields of ``repeats`` OK fits of ring-downs at ``current_a`` and θ0 (what a fit
    reports of frequency, its σ, start amplitude, damping and duration)."""
    source = BENCH.environment.source
    if current_a:
        source = SumSource((source, BENCH.supply.source.scaled(current_a)))
    start = BENCH.probe.theta_stop_rad * math.exp(-BENCH.probe.damping_per_s * COIL_OFF_SKIP_S)
    truth = float(true_frequency_hz(BENCH.probe, source, [theta0_rad], start, duration_s=0.5)[0])
    common = dict(
        theta0_rad=theta0_rad, frequency_std_hz=STD_HZ, amplitude_rad=start, damping_per_s=1.8, duration_s=0.5
    )
    return [dict(common, frequency_hz=truth + STD_HZ * rng.standard_normal()) for _ in range(repeats)]
