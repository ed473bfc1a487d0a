"""The difference channel's white noise floor from the noise model (used to plan tracking)."""

import numpy as np

from mows.physics.fluxgate import NoiseModel
from mows.sim.noise import NoiseStream
from mows.sim.scenario import load_scenario


def test_the_difference_floor_is_what_the_simulated_sensors_give():
    scenario = load_scenario("anti_helmholtz")
    fs = scenario.sample_rate_hz
    noise = NoiseStream(scenario.noise, fs, np.random.default_rng(3)).draw(0, 200_000)
    measured = float(np.std(noise[:, 0] - noise[:, 1]))  # the common-mode noise cancels in the difference
    assert abs(measured / scenario.noise.difference_white_std_t(fs) - 1.0) < 0.01
    # Each sensor's one-sided ASD a over fs/2 gives a·√(fs/2); two independent ones, √2 times that.
    assert np.isclose(NoiseModel(sensor_white_t_per_rthz=1e-11).difference_white_std_t(8.0), 1e-11 * 2.0 * np.sqrt(2))
