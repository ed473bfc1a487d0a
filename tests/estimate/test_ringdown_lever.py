"""The fit's signal model against the simulator's exact pickup of a magnet on a lever.

On the paper's 1.9 mm lever the magnet also moves across the sensor line, which Eq. S11
(a magnet turning in place) leaves out: the 0°:90° amplitude ratio becomes 8.6 instead of
15.2, and near 90° the paper's model no longer describes the data. The lever-aware pickup
(mows.physics.fluxgate.pickup_harmonics) does, at every orientation.
"""

import math

import numpy as np
import pytest

from mows.device.stream.simulated_cycle import simulate_cycle
from mows.estimate.recorded_cycle import fit_cycle
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, fit_ringdown
from mows.physics.field import UniformField
from mows.sim.scenario import load_scenario
from mows.sim.sections import Environment
from mows.sim.simulator import SimulatedDevice


@pytest.fixture(scope="module")
def cycles():
    scenario = load_scenario()
    device = SimulatedDevice(scenario, np.random.default_rng(5))
    return scenario, {
        deg: simulate_cycle(device, math.radians(deg), scenario.excitation.amplitude_a) for deg in (0, 45, 90, 135, 180)
    }


def fit(scenario, record, lever_aware):
    return fit_cycle(record, scenario, paper_model=not lever_aware)


@pytest.mark.parametrize("deg", [0, 45, 90, 135, 180])
def test_lever_aware_model_fits_and_recovers_the_swing(cycles, deg):
    scenario, records = cycles
    record = records[deg]
    result = fit(scenario, record, lever_aware=True)
    assert result.ok, result.message
    assert result.chi2_dof < 1 + 5 * math.sqrt(2 / result.n_samples)
    # The swing the stop allows (θmax ≈ 24°), which Eq. S11 misreads by up to 10°: within
    # its tolerance, or not reported.
    swing = record.ringdown_amplitude_rad() * math.exp(-scenario.probe.damping_per_s * result.start_offset_s)
    if "amplitude_rad" in result.undetermined:
        assert math.isnan(result.amplitude_rad)
    else:
        assert abs(result.amplitude_rad - swing) < FitOptions().amplitude_tolerance_rad
    truth = record.ringdown_frequency_hz(result.duration_s)
    assert abs(result.frequency_hz - truth) < 4 * result.frequency_std_hz


def test_eq_s11_does_not_describe_the_lever_at_90_degrees(cycles):
    """Eq. S11 as printed: the swing about θ0 (a free rest offset would absorb most of the
    lever's signature at 90°, as a wrong offset)."""
    scenario, records = cycles
    record = records[90]
    start = record.coil_off_index
    paper = fit_ringdown(
        record.samples_t[start:],
        record.sample_rate_hz,
        record.theta0_rad,
        record.frequency_hz,
        record.saturated[start:],
        FitOptions(rest_offset_free=False),
        scenario.probe.damping_per_s,
        COIL_OFF_SKIP_S,
    )
    exact = fit(scenario, record, lever_aware=True)
    assert paper.chi2_dof > 3 * exact.chi2_dof


@pytest.mark.parametrize("deg", [0, 180])
def test_the_swing_is_right_about_a_deflected_rest_angle(deg):
    """2 mT across the field-free axis turns the rest angle by ≈ 7.4° (at 0° and 180°): the
    swing between the stops is then 24° − 7.4°. Without the rest offset the model swings about
    θ0, and κ and θmax trade off against the missing offset (θmax came out 8.5 ± 8.3° and
    22.9 ± 2.9° at 180° where the truth is 16.5°). With it, θmax and |offset| agree with the
    simulator's truth within their tolerances, or are said to be not determined."""
    scenario = load_scenario().replace(environment=Environment(sources=(UniformField((16e-6, 2e-3, -43.6e-6)),)))
    tolerances = {"amplitude_rad": FitOptions().amplitude_tolerance_rad, "rest_offset_rad": math.radians(0.5)}
    for seed in range(3):
        device = SimulatedDevice(scenario, np.random.default_rng(seed))
        record = simulate_cycle(device, math.radians(deg), scenario.excitation.amplitude_a)
        result = fit(scenario, record, lever_aware=True)
        assert result.ok, result.message
        rest = record.potential.rest_angle_rad()
        assert abs(rest) > math.radians(7)
        swing = record.ringdown_amplitude_rad() * math.exp(-scenario.probe.damping_per_s * result.start_offset_s)
        for name, truth in (("amplitude_rad", swing), ("rest_offset_rad", rest)):
            value = getattr(result, name)
            if name in result.undetermined:
                assert math.isnan(value) and "not determined" in result.message
            else:
                assert abs(value - truth) < tolerances[name], (seed, name, result.report())
