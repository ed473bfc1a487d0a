"""The fit's θmax and rest offset ε in strong fields and gradients: right or said to be unknown.

Requirement: in fields up to 5 mT and gradients up to 50 mT/m (the paper's range), every
fit's θmax is within 1° and its ε within 0.5° of the truth, or NaN with the reason named
(``RingdownFit.undetermined``). The truth is the simulator's own record: the first swing after
the switch-off, decayed to the first fitted sample, and the exact rest angle of the potential.

Scenes: the calibration bench with its Helmholtz pair at ±2 A (±3.4 mT along x), a uniform
5 mT across x, the anti-Helmholtz pair at 50 mT/m, the tilted plane and the nearby coil, θ0
every 30°, five seeds each. Short ring-downs (0.25 s) keep the simulation lean; they determine
θmax and ε less often, which the requirement allows but never lets pass as a number.

In a strong field the cost over (θmax, ε) has several minima; a fit that only descends from
its spectral start lands in whichever is nearest, with a small σ. The last test shows that on
the calibration bench at +2 A and θ0 = 90°: the local optimum puts ε more than 3° from the
truth, so a fit that reported it would fail the requirement.
"""

import math

import numpy as np
import pytest

from mows.device.stream.simulated_cycle import simulate_cycle
from mows.estimate.recorded_cycle import fit_cycle
from mows.estimate.ringdown import FitOptions, starting_point
from mows.estimate.ringdown.problem import RingdownProblem, variable_projection
from mows.estimate.ringdown.start import white_noise_std
from mows.physics.field import UniformField, source_from_dict
from mows.sim.scenario import load_scenario
from mows.sim.sections import Environment
from mows.sim.simulator import SimulatedDevice

RINGDOWN_S = 0.25
SEEDS = 5
ANGLES_DEG = range(0, 360, 30)
EARTH_T = (16e-6, 12e-6, -43.6e-6)
TOLERANCE_RAD = {"amplitude_rad": math.radians(1.0), "rest_offset_rad": math.radians(0.5)}


def scenes():
    """(name, scenario, supply current or None)."""
    base = load_scenario()
    pair_50mt_per_m = {
        "type": "anti_helmholtz",
        "center_m": [0.0, 0.0, 0.0],
        "axis": [1.0, 0.0, 0.0],
        "radius_m": 0.105,
        "turns": 200,
        "current_a": -2.55,  # Gxx ≈ −50 mT/m at the probe
    }
    return [
        ("calibration +2 A", load_scenario("calibration"), 2.0),
        ("calibration −2 A", load_scenario("calibration"), -2.0),
        (
            "5 mT across x",
            base.replace(environment=Environment(sources=(UniformField((16e-6, 5e-3, -43.6e-6)),))),
            None,
        ),
        (
            "anti-Helmholtz 50 mT/m",
            base.replace(environment=Environment(sources=(UniformField(EARTH_T), source_from_dict(pair_50mt_per_m)))),
            None,
        ),
        ("tilted plane", load_scenario("tilted_plane"), None),
        ("nearby coil", load_scenario("nearby_coil"), None),
    ]


def truth(scenario, record, fit) -> dict:
    swing = record.ringdown_amplitude_rad() * math.exp(-scenario.probe.damping_per_s * fit.start_offset_s)
    return {"amplitude_rad": swing, "rest_offset_rad": float(record.potential.rest_angle_rad())}


@pytest.fixture(scope="module")
def fits():
    out = []
    for name, scenario, current in scenes():
        for seed in range(SEEDS):
            device = SimulatedDevice(scenario, np.random.default_rng(seed))
            if current is not None:
                device.set_field_current(current)
            for deg in ANGLES_DEG:
                record = simulate_cycle(
                    device, math.radians(deg), scenario.excitation.amplitude_a, ringdown_s=RINGDOWN_S
                )
                fit = fit_cycle(record, scenario)
                out.append((name, seed, deg, fit, truth(scenario, record, fit)))
    return out


@pytest.mark.slow
def test_theta_max_and_rest_offset_are_right_or_not_reported(fits):
    assert len(fits) >= 6 * SEEDS * 12
    wrong = []
    for name, seed, deg, fit, true in fits:
        assert fit.ok, (name, seed, deg, fit.message)
        for parameter, tolerance in TOLERANCE_RAD.items():
            value = getattr(fit, parameter)
            if parameter in fit.undetermined:
                assert math.isnan(value) and "not determined" in fit.message, (name, deg, fit.message)
            elif not abs(value - true[parameter]) <= tolerance:
                wrong.append((name, seed, deg, parameter, math.degrees(value), math.degrees(true[parameter])))
    assert not wrong, wrong
    # Somewhere the data do pin the offset: the test exercises reported numbers, not only NaN.
    assert sum(math.isfinite(fit.rest_offset_rad) for *_, fit, _ in fits) >= 20


def test_a_local_fit_lands_in_a_wrong_minimum_that_the_fit_does_not_report():
    scenario = load_scenario("calibration")
    device = SimulatedDevice(scenario, np.random.default_rng(0))
    device.set_field_current(2.0)
    record = simulate_cycle(device, math.radians(90), scenario.excitation.amplitude_a, ringdown_s=0.5)
    fit = fit_cycle(record, scenario)
    rest = float(record.potential.rest_angle_rad())
    assert abs(rest) > math.radians(10)
    # The descent from the spectral start alone (the same model, data and weights).
    options = FitOptions.lever_aware(scenario.sensors.pair, scenario.probe, record.theta0_rad)
    start = record.coil_off_index + int(round(fit.start_offset_s * record.sample_rate_hz))
    y = (record.samples_t[start:, 0] - record.samples_t[start:, 1])[None, :]
    problem = RingdownProblem(
        y,
        np.array([1.0 / white_noise_std(y[0])]),
        1.0 / record.sample_rate_hz,
        options.pickup_at(record.theta0_rad)[None, :],
        True,
    )
    q0 = starting_point(y[0], record.sample_rate_hz, record.theta0_rad, record.frequency_hz, options)
    local, converged, _, _ = variable_projection(problem, q0[:5], options.max_iterations, 1e-4)
    assert abs(local.q[4] - rest) > math.radians(3)
    assert math.isnan(fit.rest_offset_rad) or abs(fit.rest_offset_rad - rest) <= TOLERANCE_RAD["rest_offset_rad"]
