"""A simulated cycle is the driver's: its sequencer's phases in device time, its refusals, and
its record's samples where the device produced them."""

import math

import numpy as np
import pytest

from mows.device.stream.simulated_cycle import cycles_npz, simulate_cycle
from mows.physics.coils import excitation_samples
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice


@pytest.fixture(scope="module")
def scenario():
    return load_scenario()


def test_the_coils_drive_until_the_switch_off_and_the_settling_passes_in_device_time(scenario):
    device = SimulatedDevice(scenario, np.random.default_rng(1))
    first = simulate_cycle(device, 0.0, 2.0, excite_s=0.3, ringdown_s=0.2)
    second = simulate_cycle(device, math.radians(90.0), 2.0, excite_s=0.3, ringdown_s=0.2, settle_s=1.5)
    fs = scenario.sample_rate_hz
    for record in (first, second):
        off = record.coil_off_index
        assert off == excitation_samples(0.3, record.frequency_hz, fs)  # at the drive current's peak
        assert record.block.coils_on[:off].all() and not record.block.coils_on[off:].any()
        assert len(record.samples_t) - off == round(0.2 * fs)
        np.testing.assert_array_equal(record.currents_a, scenario.setup.currents_a(record.theta0_rad, 2.0))
    ended = first.block.samples.first_sample_index + len(first.samples_t)
    assert second.block.samples.first_sample_index - ended >= round(1.5 * fs)  # turned, then settled


def test_a_current_above_the_setup_s_cap_is_refused_by_the_sequencer(scenario):
    device = SimulatedDevice(scenario)
    above = 1.01 * scenario.setup.cap.limit_a
    with pytest.raises(ValueError, match="exceeds the cap"):
        simulate_cycle(device, 0.0, above, excite_s=0.2, ringdown_s=0.1)


def test_the_cycles_arrays_pad_each_cycle_to_the_longest(scenario):
    device = SimulatedDevice(scenario)
    records = [simulate_cycle(device, math.radians(deg), 2.0, excite_s=0.2, ringdown_s=0.1) for deg in (0, 90)]
    arrays = cycles_npz(records, "name: x")
    lengths = [len(r.samples_t) for r in records]
    assert list(arrays["n_samples"]) == lengths and arrays["samples_t"].shape[1] == max(lengths)
    for samples, n in zip(arrays["samples_t"], lengths):
        assert np.isfinite(samples[:n]).all() and np.isnan(samples[n:]).all()
    assert arrays["scenario_yaml"] == "name: x"
