"""Tracking mode: B along the probe axis from short kicks and ring-downs at one orientation.

Every fit must lie in a stretch with the coils off and no sensor saturated: checked against the
simulated device's own record of its coils, and against a saturated stretch put into a window.
"""

import dataclasses
import math

import numpy as np
import pytest

from device.test_cycle import session_on_simulator
from mows.bench.rig import DeviceTimeRig, max_duty_fraction
from mows.bench.throughput import CAP_A
from mows.device.cycle.phases import CycleOutcome, CycleRequest, CycleSettings, Phase
from mows.device.cycle.tracking import TrackingLoop, TrackingSettings
from mows.device.cycle.tracking_plan import plan_tracking, tracking_plan
from mows.estimate.probe_set import ProbeEntry
from mows.estimate.ringdown import FitOptions
from mows.estimate.segments import RingdownWindow, Segment, fit_segment
from mows.sim.scenario import load_scenario
from mows.sweep.fast_cycle import fit_std_model

DUTY = CycleSettings(max_duty_cycle=0.2, duty_window_s=2.0, turn_settle_s=0.2)  # tighter than the kicks want
CLIPPING_RANGE_T = 0.2e-6  # a near sensor this narrow clips the first swings of a ring-down from the stop


def run_tracking(scenario, settings: CycleSettings, ringdowns: int):
    """The driver's tracking mode (its plan and loop) on the simulated device, in device time."""
    rig = DeviceTimeRig(scenario, settings, CAP_A, seed=11)
    plan = tracking_plan(scenario, 0.0, 1e-6, CAP_A, fit_std_model(scenario, rig.first_block_noise_std_t()))
    loop = TrackingLoop()
    loop.start(TrackingSettings(0.0, CAP_A, plan.excite_s, plan.ringdown_s))
    return rig, plan, loop, rig.run_tracking(loop, ringdowns)


def fitted(m, fs: float) -> tuple[int, int]:
    """[first, last) of the samples a fit used, counted from its window's start."""
    first = round(m.fit.start_offset_s * fs)
    return first, first + m.fit.n_samples


@pytest.fixture(scope="module")
def tracked():
    """Under a duty-cycle limit tighter than the kicks would keep by themselves."""
    return run_tracking(load_scenario("anti_helmholtz"), DUTY, 30)


@pytest.fixture(scope="module")
def clipped():
    """With a near sensor that saturates during the first swings of every ring-down."""
    scenario = load_scenario("anti_helmholtz")
    pair = scenario.sensors.pair
    near = dataclasses.replace(pair.sensors[0], range_t=CLIPPING_RANGE_T)
    sensors = dataclasses.replace(scenario.sensors, pair=dataclasses.replace(pair, sensors=(near, pair.sensors[1])))
    return run_tracking(scenario.replace(sensors=sensors), CycleSettings(turn_settle_s=0.2), 12)


def test_every_tracking_fit_lies_where_the_coils_were_off(tracked):
    rig, _, loop, measured = tracked
    assert loop.on and loop.cycles >= 2  # chained cycles, not one long one
    assert len(measured) >= 30 and all(m.fit.ok for m in measured), [m.fit.report() for m in measured]
    on = rig.coil_intervals()
    assert len(on) == len(measured)
    for m in measured:
        start = round(m.window.start_ns * rig.fs / 1e9)
        first, last = fitted(m, rig.fs)
        assert all(start + last <= a or start + first >= b for a, b in on), (start, first, last, on)
        assert first > 0  # the coil current's decay and the recovery are left out


def test_tracking_never_fits_across_a_saturated_stretch(clipped):
    rig, _, _, measured = clipped
    assert all(m.saturated.any() for m in measured)  # every window starts clipped
    fits = [m for m in measured if m.fit.ok]
    assert fits, [m.fit.report() for m in measured]
    for m in fits:
        first, last = fitted(m, rig.fs)
        assert not m.saturated[first:last].any()
        assert m.saturated[:first].any()  # it starts after the clipped swings
    # A window whose unclipped stretch is too short is refused, never fitted across the clipping.
    assert all(m.fit.status.name == "SATURATED" for m in measured if not m.fit.ok)


def test_tracking_keeps_the_current_cap_and_the_duty_limit(tracked):
    rig, plan, _, _ = tracked
    assert rig.peak_current_a <= CAP_A
    kicks = np.array([b - a for a, b in rig.coil_intervals()]) / rig.fs
    assert np.allclose(kicks, plan.excite_s, atol=2.0 / rig.fs)
    # Unlimited, the kicks would take excite/(excite + ring-down) of the time; the limit holds instead.
    assert plan.excite_s / (plan.excite_s + plan.ringdown_s) > DUTY.max_duty_cycle
    assert max_duty_fraction(rig.coil_intervals(), round(DUTY.duty_window_s * rig.fs)) <= DUTY.max_duty_cycle


def test_tracking_is_off_until_started_and_a_failed_cycle_ends_it():
    loop = TrackingLoop()
    assert not loop.on and loop.next_request(CycleSettings()) is None
    loop.start(TrackingSettings(0.3, CAP_A, 0.05, 0.2))
    first = loop.next_request(CycleSettings())
    assert (
        first.theta0_rad == 0.3 and first.settings.turn_settle_s == CycleSettings().turn_settle_s
    )  # turns and settles
    assert first.settings.tuning_steps == 0 and first.settings.gap_s == 0.0
    loop.on_outcome(CycleOutcome(True, "", 1, 110.0, first.settings.repeats))
    assert loop.next_request(CycleSettings()).settings.turn_settle_s == 0.0  # the stage has not moved
    loop.on_outcome(CycleOutcome(False, "emergency stop: test", 2, 110.0, 0))
    assert not loop.on and "emergency stop" in loop.stopped_reason
    assert loop.next_request(CycleSettings()) is None


def tracking_session(current_a=CAP_A):
    session = session_on_simulator(CycleSettings(turn_settle_s=0.0))
    session.set_tracking(TrackingSettings(0.0, current_a, 0.05, 0.2))
    return session


def test_the_session_chains_tracking_cycles_refuses_other_cycles_and_stops_on_the_emergency_stop():
    session = tracking_session()
    events = []
    for _ in range(20_000):
        events += session.step(0.0).events
        if session.tracking.cycles >= 2:
            break
    assert session.tracking.cycles >= 2 and session.tracking.on
    assert len({e.cycle_id for e in events if e.phase == Phase.RINGDOWN}) >= 2
    with pytest.raises(ValueError, match="tracking"):
        session.start_cycle(CycleRequest(0.0), lambda _: None)
    session.emergency_stop(True, "test")
    assert not session.tracking.on and "emergency stop" in session.tracking.stopped_reason
    assert not session.backend.device.coils_on
    session.emergency_stop(False, "")
    for _ in range(200):
        session.step(0.0)
    assert not session.sequencer.busy  # released, tracking stays off until it is started again


def test_a_kick_above_the_cap_is_never_sent_and_ends_tracking():
    session = tracking_session(current_a=2.0 * CAP_A)
    for _ in range(200):
        session.step(0.0)
    assert not session.tracking.on and "cap" in session.tracking.stopped_reason
    assert not session.backend.device.coil_log


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
    line = ProbeEntry(0, probe, probe.f00_hz).line(0.0, scenario.sensors.pair, "difference", probe.f00_hz)
    (fit,) = fit_segment(
        Segment(window, 0, fs, samples, saturated, 0), [line], options=FitOptions(theta_stop_rad=probe.theta_stop_rad)
    )
    assert fit.ok, fit.report()
    first, last = round(fit.start_offset_s * fs), round(fit.start_offset_s * fs) + fit.n_samples
    assert first >= int(0.12 * fs) or last <= int(0.1 * fs)


def test_a_target_below_the_bound_is_reported_with_the_bound():
    scenario = load_scenario("anti_helmholtz")
    std = fit_std_model(scenario, 1.4e-9)
    plan = plan_tracking(scenario.probe, scenario.setup, scenario.pose, std, 0.0, 1e-9, CAP_A)
    assert not plan.feasible and plan.bound_std_t > 1e-9
    reachable = plan_tracking(scenario.probe, scenario.setup, scenario.pose, std, 0.0, 0.2e-6, CAP_A)
    assert reachable.feasible and reachable.bound_std_t <= 0.2e-6
    # A looser target allows shorter ring-downs, hence more updates per second.
    looser = plan_tracking(scenario.probe, scenario.setup, scenario.pose, std, 0.0, 1e-6, CAP_A)
    assert looser.updates_per_s > reachable.updates_per_s
