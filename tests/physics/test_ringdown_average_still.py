"""A ring-down that starts without swing in the averaging of a constant-frequency fit.

A sweep's first-principles model gives a start swing of 0 where the housing stop lies inside
the rest deflection: the field holds the lever on its stop and nothing rings. The phase weight
then vanishes over the whole window, so no fit exists whose frequency the kernel could average.

Requirement: such a ring-down's kernel, nodes and node weights are NaN, without a warning (a
number there would be made up: the weights (1, 0, 0) stood for a kernel nothing determines),
and a swing of 1e-5 rad, which rings however little, still has a kernel summing to 1, with
every node between 0 and the start swing. The same holds for the exact pickup of the magnet
on its lever and for a zero pickup (no phase information at any swing).
"""

import math
import warnings

import numpy as np
import pytest

from mows.physics.fluxgate import FluxgatePair, pickup_harmonics
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE
from mows.physics.ringdown_average import amplitude_nodes, averaging_kernel

DAMPING_PER_S, DURATION_S, SMALL_RAD = 1.8, 0.5, 1e-5


def lever_pickup(theta0_rad):
    pose = Pose(theta0_rad=theta0_rad)
    return np.array(pickup_harmonics(FluxgatePair.paper(), pose, PAPER_PROBE.lever_m, PAPER_PROBE.moment_am2))


def averaged(theta0_rad, swing_rad, pickup):
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        _, mass = averaging_kernel(theta0_rad, swing_rad, DAMPING_PER_S, DURATION_S, pickup=pickup)
        amplitudes, weights = amplitude_nodes(theta0_rad, swing_rad, DAMPING_PER_S, DURATION_S, pickup=pickup)
    return mass, amplitudes, weights


@pytest.mark.parametrize("theta0_deg, lever", [(0.0, False), (90.0, False), (30.0, True), (90.0, True)])
def test_a_lever_on_its_stop_has_no_kernel_and_the_smallest_swing_has_one(theta0_deg, lever):
    theta0 = math.radians(theta0_deg)
    pickup = lever_pickup(theta0) if lever else None
    for result in averaged(theta0, 0.0, pickup):
        assert np.all(np.isnan(result))
    mass, amplitudes, weights = averaged(theta0, SMALL_RAD, pickup)
    assert mass.sum() == pytest.approx(1.0, abs=1e-12) and weights.sum() == pytest.approx(1.0, abs=1e-12)
    assert np.all((amplitudes > 0.0) & (amplitudes < SMALL_RAD))


def test_a_zero_pickup_has_no_kernel_at_any_swing():
    for result in averaged(0.0, 0.3, np.zeros(3)):
        assert np.all(np.isnan(result))
