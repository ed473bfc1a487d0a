"""The static-field supply: cap, resolution and slew (paper, Methods), in the simulator and the
scheduled device, and the frequency the probe takes in its field."""

import math

import numpy as np
import pytest
import scipy.constants

from mows.device.simulated.scheduled import ScheduledDevice
from mows.physics.coils import CurrentCap
from mows.physics.field import helmholtz_pair
from mows.physics.probe import PAPER_PROBE
from mows.physics.supply import FieldSupply, SupplyLimits, supply_from_dict
from mows.sim.scenario import Scenario, load_scenario
from mows.sim.simulator import SimulatedDevice

PASCO = helmholtz_pair((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.105, 200, 1.0)


def test_currents_above_the_cap_are_refused_and_settings_rounded_to_a_tenth_of_a_milliampere():
    limits = SupplyLimits()
    assert limits.cap_a == 2.0 and limits.resolution_a == 1e-4
    assert limits.check(0.12346) == pytest.approx(0.1235, abs=1e-12)
    assert limits.check(0.12344) == pytest.approx(0.1234, abs=1e-12)
    assert limits.check(-2.0) == -2.0
    for bad in (2.0001, -2.5, math.nan, math.inf, True, "1"):
        with pytest.raises(ValueError):
            limits.check(bad)


def test_a_unipolar_supply_refuses_a_negative_current_naming_it_and_its_range():
    limits = SupplyLimits(polarity="unipolar")
    assert limits.min_current_a == 0.0 and SupplyLimits().min_current_a == -2.0  # bipolar unless said
    assert limits.check(0.0) == 0.0 and limits.check(2.0) == 2.0 and limits.check(-0.0) == 0.0
    with pytest.raises(
        ValueError, match=r"^supply current -0\.5 A is outside the supply's range 0 … \+2 A \(unipolar\)"
    ):
        limits.check(-0.5)
    with pytest.raises(ValueError, match="unipolar"):
        limits.ramp(1.0, -1.0)
    with pytest.raises(ValueError, match="polarity = 'both'"):
        SupplyLimits(polarity="both")


def test_a_scenario_supply_says_its_polarity_and_the_scheduled_device_keeps_to_it():
    scenario = load_scenario("calibration")
    assert scenario.supply.limits.polarity == "bipolar"  # the simulated supply stays bipolar
    data = scenario.supply.to_dict() | {"polarity": "unipolar"}
    unipolar = scenario.replace(supply=supply_from_dict(data))
    assert supply_from_dict(unipolar.supply.to_dict()).limits.polarity == "unipolar"
    device = ScheduledDevice(SimulatedDevice(unipolar), CurrentCap(), supply_cap_a=1.0)
    assert device.supply_limits.range_text == "0 … +1 A (unipolar)"  # the driver's cap, the supply's sign
    with pytest.raises(ValueError, match="-0.5 A is outside"):
        device.schedule_field_current(0, -0.5)
    assert device.supply_target_a == 0.0


def test_a_ramp_never_steps_faster_than_the_slew_limit_and_ends_on_the_target():
    limits = SupplyLimits(slew_a_per_s=2.0)
    ramp = limits.ramp(-0.5, 1.5)
    times, currents = np.array(ramp).T
    assert currents[-1] == 1.5 and times[-1] == pytest.approx(1.0 - 0.01)  # 2 A at 2 A/s in 10 ms steps
    steps = np.abs(np.diff(np.concatenate([[-0.5], currents])))
    assert steps.max() <= 2.0 * 0.01 + 1e-4  # slew × step, ± resolution
    assert np.all(np.diff(times) == pytest.approx(0.01))


def test_the_probe_takes_the_frequency_of_the_helmholtz_field_it_is_given():
    # Independent physics: the Helmholtz pair's centre field (4/5)^(3/2)·μ0·N·I/R along x;
    # at θ0 = 0 a uniform Bx adds m·Bx to the spring exactly (U = ½kMθ² − m·B·cos θ), Eq. S1.
    device = SimulatedDevice(Scenario(supply=FieldSupply(PASCO)))
    for current in (0.5, -1.25, 2.0):
        device.set_field_current(current)
        field = 0.8**1.5 * scipy.constants.mu_0 * 200 * current / 0.105
        expected = PAPER_PROBE.frequency_for_spring_hz(PAPER_PROBE.spring_nm_per_rad + PAPER_PROBE.moment_am2 * field)
        assert device.expected_frequencies_hz()[0] == pytest.approx(float(expected), rel=1e-7)
    with pytest.raises(ValueError, match="cap"):
        device.set_field_current(2.5)
    with pytest.raises(ValueError, match="no field supply"):
        SimulatedDevice(Scenario()).set_field_current(0.1)


def scheduled(slew_a_per_s=2.0):
    scenario = Scenario(supply=FieldSupply(PASCO, SupplyLimits(slew_a_per_s=slew_a_per_s)))
    return ScheduledDevice(SimulatedDevice(scenario), CurrentCap())


def currents_over(device, end_index, every=100):
    """The supply current after each ``every`` samples up to ``end_index``."""
    trace = []
    while device.next_index < end_index:
        device.read_until(min(end_index, device.next_index + every))
        trace.append(device.device.field_current_a)
    return np.array(trace)


def test_the_scheduled_device_ramps_within_the_slew_limit_and_says_when_it_arrives():
    device = scheduled()
    reached = device.schedule_field_current(1000, 1.0)
    assert reached == 1000 + round(0.49 * 20_000)  # 50 steps of 10 ms, the first at once
    trace = currents_over(device, reached + 1)
    assert trace[0] == 0.0 and trace[-1] == 1.0
    per_5ms = np.abs(np.diff(trace))
    assert per_5ms.max() <= 0.02 + 1e-9  # 2 A/s: at most one 10 mA step per 5 ms read
    with pytest.raises(ValueError, match="cap"):
        device.schedule_field_current(device.next_index, -2.1)
    assert device.supply_target_a == 1.0


def test_supply_to_zero_ramps_down_from_wherever_a_ramp_was_and_cancelling_the_coils_leaves_it():
    device = scheduled()
    device.schedule_field_current(0, 2.0)
    device.read_until(round(0.3 * 20_000))
    device.cancel()  # the coils' cancel: the ramp goes on
    device.read_until(round(0.5 * 20_000))
    midway = device.device.field_current_a
    assert 0.9 < midway < 1.1
    zero = device.supply_to_zero()
    assert zero - device.next_index == round((midway / 2.0 - 0.01) * 20_000)
    trace = currents_over(device, zero + 1)
    assert trace[-1] == 0.0 and np.all(np.diff(trace) <= 0.0)


def test_the_shipped_calibration_bench_puts_1_7_mT_per_ampere_on_the_probe():
    scenario = load_scenario("calibration")
    field = scenario.supply.source.field_t(np.zeros(3))
    assert field[0] == pytest.approx(0.8**1.5 * scipy.constants.mu_0 * 200 / 0.105, rel=1e-9)
    assert scenario.supply.limits == SupplyLimits(cap_a=2.0, slew_a_per_s=2.0, resolution_a=1e-4)
    assert abs(scenario.probe.spring_nm_per_rad / PAPER_PROBE.spring_nm_per_rad - 1.0) > 0.05
