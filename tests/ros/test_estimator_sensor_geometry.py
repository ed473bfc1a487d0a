"""The estimator's fluxgate geometry: the pair its parameters describe is where a scene puts its
sensors, along any line from the probe (the three-probe scene's pair stands above the probes,
along the rotation plane's normal), and a direction that is none is refused."""

import numpy as np
import pytest

from mows.estimate.settings import FitParameters
from mows.physics.fluxgate import PAPER_DISTANCE_M
from mows.sim.scenario import load_scenario
from mows_estimator.parameters import PARAMETERS

pytestmark = pytest.mark.ros

DEFAULTS = {spec.name: spec.default for spec in PARAMETERS}
DIRECTION = next(spec for spec in PARAMETERS if spec.name == "sensor_direction")


def test_the_default_is_the_papers_pair_along_x():
    pair = FitParameters.of(DEFAULTS).fluxgate_pair()
    assert pair.positions_m[0] == pytest.approx([PAPER_DISTANCE_M, 0.0, 0.0])
    assert pair.sensors[0].axis == pytest.approx([0.0, 1.0, 0.0])


def test_a_pair_above_the_probes_is_the_three_probe_scenes_pair():
    scene = load_scenario("three_probes").sensors.pair
    values = {**DEFAULTS, "sensor_distance_m": 0.02, "sensor_spacing_m": 0.03, "sensor_direction": [0.0, 0.0, 2.0]}
    pair = FitParameters.of(values).fluxgate_pair()
    np.testing.assert_allclose(pair.positions_m, scene.positions_m, atol=1e-15)
    for ours, theirs in zip(pair.sensors, scene.sensors):
        np.testing.assert_allclose(ours.axis, theirs.axis)


@pytest.mark.parametrize("value", [[0.0, 0.0, 0.0], [1.0, 0.0], [1.0, float("nan"), 0.0]])
def test_a_direction_that_is_none_is_refused_naming_it(value):
    problem = DIRECTION.check(value)
    assert problem is not None and problem.startswith("sensor_direction = ")
