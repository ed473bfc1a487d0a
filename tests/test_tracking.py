"""Tracking mode: B along the probe axis from short kicks and ring-downs at one orientation.

Every fit must lie in a stretch with the coils off and no sensor saturated: checked against the
simulated device's own record of its coils, and against a saturated stretch put into a window.
"""

import math

import numpy as np
import pytest

from mows.bench.rig import DeviceTimeRig
from mows.bench.throughput import CAP_A
from mows.device.phases import CycleRequest, CycleSettings
from mows.estimate.ringdown import FitOptions
from mows.estimate.segments import RingdownWindow, Segment, fit_segment
from mows.sim.scenario import load_scenario
from mows.sweep.fast_cycle import plan_tracking, ringdown_std_model


@pytest.fixture(scope="module")
def tracked():
    scenario = load_scenario("anti_helmholtz")
    probe = scenario.probe
    rig = DeviceTimeRig(scenario, CycleSettings(), CAP_A, seed=11)
    std = ringdown_std_model(
        scenario.sensors.pair, probe, scenario.pose, scenario.sample_rate_hz, rig.first_block_noise_std_t()
    )
    plan = plan_tracking(probe, scenario.setup, scenario.pose, std, 0.0, 1e-6, CAP_A)
    rig.set_settings(
        CycleSettings(
            excitation_current_a=CAP_A,
            excite_s=plan.excite_s,
            ringdown_s=plan.ringdown_s,
            gap_s=0.0,
            repeats=8,
            tuning_steps=0,
            settle_s=0.5,
        )
    )
    ok, message, measured = rig.run_cycle(CycleRequest(0.0, frequency_hz=probe.f00_hz))
    assert ok, message
    return rig, plan, measured


def test_every_tracking_fit_lies_where_the_coils_were_off(tracked):
    rig, _, measured = tracked
    assert len(measured) == 8 and all(m.fit.ok for m in measured), [m.fit.report() for m in measured]
    on = rig.coil_intervals()
    assert len(on) == 8
    for m in measured:
        first = round(m.window.start_ns * rig.fs / 1e9 + m.fit.start_offset_s * rig.fs)
        last = first + m.fit.n_samples  # exclusive
        assert all(last <= a or first >= b for a, b in on), (first, last, on)
        assert m.fit.start_offset_s > 0.0  # the coil current's decay and the recovery are left out


def test_tracking_keeps_the_current_cap_and_the_duty_limit(tracked):
    rig, plan, _ = tracked
    assert rig.peak_current_a <= CAP_A
    kicks = np.array([b - a for a, b in rig.coil_intervals()]) / rig.fs
    assert np.allclose(kicks, plan.excite_s, atol=2.0 / rig.fs)
    assert rig.sequencer.duty_fraction() <= CycleSettings().max_duty_cycle


def test_a_saturated_stretch_inside_a_window_is_never_fitted_across():
    scenario = load_scenario("anti_helmholtz")
    probe, fs = scenario.probe, scenario.sample_rate_hz
    t = np.arange(int(0.3 * fs)) / fs
    signal = 1e-7 * np.exp(-probe.damping_per_s * t) * np.cos(2 * math.pi * probe.f00_hz * t)
    samples = np.stack([signal, np.zeros_like(signal)], axis=1) + np.random.default_rng(1).normal(0, 1e-9, (t.size, 2))
    saturated = np.zeros(samples.shape, bool)
    saturated[int(0.1 * fs) : int(0.12 * fs), 0] = True  # e.g. a passing disturbance
    samples[saturated] = 1e-5
    window = RingdownWindow(0, 0.3, theta0_rad=0.0, excitation_frequency_hz=probe.f00_hz)
    fit = fit_segment(
        Segment(window, 0, fs, samples, saturated, 0), FitOptions.lever_aware(scenario.sensors.pair, probe, 0.0)
    )
    assert fit.ok, fit.report()
    first, last = round(fit.start_offset_s * fs), round(fit.start_offset_s * fs) + fit.n_samples
    assert first >= int(0.12 * fs) or last <= int(0.1 * fs)


def test_a_target_below_the_bound_is_reported_with_the_bound():
    scenario = load_scenario("anti_helmholtz")
    std = ringdown_std_model(scenario.sensors.pair, scenario.probe, scenario.pose, scenario.sample_rate_hz, 1.4e-9)
    plan = plan_tracking(scenario.probe, scenario.setup, scenario.pose, std, 0.0, 1e-9, CAP_A)
    assert not plan.feasible and plan.bound_std_t > 1e-9
    reachable = plan_tracking(scenario.probe, scenario.setup, scenario.pose, std, 0.0, 0.2e-6, CAP_A)
    assert reachable.feasible and reachable.bound_std_t <= 0.2e-6
    # A looser target allows shorter ring-downs, hence more updates per second.
    looser = plan_tracking(scenario.probe, scenario.setup, scenario.pose, std, 0.0, 1e-6, CAP_A)
    assert looser.updates_per_s > reachable.updates_per_s
