"""The simulated device starts its probes where they rest, one probe or several, buckled or not.

Requirement: beyond spring cancellation a probe's rest is off zero (the minimum of its energy
U = ½kM·θ² − m·B·cos θ, found here by scipy on that formula), and a scene of one probe takes the
same path as a scene of several: the device's truth says that rest, its probes start there and
stay there (no swing out of a rest that was not one).
"""

import math

import numpy as np
import pytest
from scipy import optimize

from mows.physics.field import UniformField
from mows.physics.fluxgate import NoiseModel
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE as P
from mows.sim.scenario import Environment, Scenario
from mows.sim.sections import SceneProbe
from mows.sim.simulator import SimulatedDevice

KM, M = P.spring_nm_per_rad, P.moment_am2
FIELD_T = 1.02 * P.cancellation_field_t  # along x, 2 % past cancellation for a probe turned to 0°


def scene(*probes: SceneProbe) -> Scenario:
    return Scenario(probes=probes, environment=Environment((UniformField((FIELD_T, 0.0, 0.0)),)), noise=NoiseModel())


def buckled_rest_rad() -> float:
    """The positive well of U = ½kM·θ² − m·B·cos θ (its two wells are alike)."""
    energy = lambda t: 0.5 * KM * t**2 - M * FIELD_T * math.cos(t)  # noqa: E731
    return optimize.minimize_scalar(energy, bounds=(1e-3, 0.7), method="bounded", options={"xatol": 1e-12}).x


def test_a_lone_buckled_probe_starts_at_its_buckled_rest_and_stays_there():
    device = SimulatedDevice(scene(SceneProbe(P, Pose())))
    rest = device.truth.rest_angle_rad
    assert rest[0] == pytest.approx(buckled_rest_rad(), abs=1e-7)  # Brent's minimum: good to √ε of the angle
    theta, _ = device.integrate(4000)
    assert np.abs(theta[:, 0] - rest[0]).max() < 1e-7


def test_a_buckled_probe_and_its_neighbour_start_at_their_coupled_rest_and_stay_there():
    """Probe 0 buckles; probe 1, 3.2 cm away and turned along the field, is stiffened (the rests
    against the total energy are tests/physics/test_coupling.py's)."""
    buckled = SceneProbe(P, Pose())
    stiff = SceneProbe(P, Pose(magnet_position_m=(0.02, 0.025, 0.0), theta0_rad=math.pi))
    device = SimulatedDevice(scene(buckled, stiff))
    rest = device.truth.rest_angle_rad
    assert math.radians(15.0) < abs(rest[0]) < math.radians(25.0)
    # 2 % past cancellation the buckle is steep in the field: the neighbour's few µT move it by mrad.
    assert abs(rest[0]) == pytest.approx(buckled_rest_rad(), abs=1e-2)
    theta, _ = device.integrate(4000)
    assert np.abs(theta - rest).max() < 1e-7
