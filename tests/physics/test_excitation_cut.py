"""Where the excitation is cut decides the swing a ring-down starts with.

Driven into the housing stop, the probe has the stop's swing only at its turning points; cut
mid-swing, the ring-down misses the drive's work of the rest of the swing (≈ m·b·I/(kM·A),
1.4 % for the calibration probe at 2 A). The decompositions and the calibration take every
ring-down's start from the stop, so the cut must land on a turning point whatever f·excite_s.
"""

import math

import numpy as np
import pytest

from mows.device.stream.simulated_cycle import simulate_cycle
from mows.physics.coils import excitation_samples
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice


def test_ringdowns_start_at_the_stop_wherever_the_requested_excitation_ends():
    scenario = load_scenario("calibration")
    device = SimulatedDevice(scenario, np.random.default_rng(5))
    frequency = float(device.expected_frequencies_hz()[0])
    stop_deg = math.degrees(scenario.probe.theta_stop_rad)
    # Four requested lengths an eighth of a drive period apart: the phase of a cut after a
    # fixed time would step through 45°, 90°, 135° of the swing.
    swings_deg = [
        math.degrees(
            simulate_cycle(
                device, 0.0, scenario.excitation.amplitude_a, excite_s=0.5 + k / (8.0 * frequency)
            ).ringdown_amplitude_rad()
        )
        for k in range(4)
    ]
    assert np.ptp(swings_deg) < 0.1, swings_deg
    assert all(stop_deg - 0.1 < s < stop_deg + 0.1 for s in swings_deg), swings_deg


def test_the_cut_is_an_odd_number_of_quarter_drive_periods_near_the_request():
    fs, f = 20_000.0, 125.0
    n = excitation_samples(0.5, f, fs)
    quarters = n / fs * 4.0 * f
    assert quarters == pytest.approx(round(quarters), abs=4.0 * f / fs) and round(quarters) % 2 == 1
    assert abs(n / fs - 0.5) <= 1.0 / (4.0 * f) + 1.0 / fs
    assert excitation_samples(0.0, f, fs) == 0
    with pytest.raises(ValueError):
        excitation_samples(0.5, 0.0, fs)
