"""The coupling of probes that share a scene, against independent physics.

Requirements: the field each probe feels of its neighbours is the exact point-dipole field of
their moments at rest (checked against the formula written out here, not the library's), its
gradient is the derivative of that field and obeys Maxwell's equations, it falls as 1/r³, it
is 1.4 µT and a few mHz at 5 cm for the paper's moment (docs/physics.md §9.10), and the coupled
rest angles are the minimum of the scene's total energy.
"""

import math

import numpy as np
import pytest
import scipy.constants
from scipy import optimize

from mows.physics.coupling import CoupledRest, PlacedProbe, coupled_frequencies_hz, coupled_rest, magnets_at
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.physics.sources import UniformField

MU0_OVER_4PI = scipy.constants.mu_0 / (4 * math.pi)
NO_FIELD = UniformField([0.0, 0.0, 0.0])


def dipole(moment, offset):
    """B = μ0/(4π)·[3·r̂(m·r̂) − m]/r³, written out independently of the library."""
    r = np.linalg.norm(offset)
    unit = offset / r
    return MU0_OVER_4PI * (3.0 * unit * (moment @ unit) - moment) / r**3


def placed(x_m, y_m=0.0, theta0_deg=0.0, e1=(1.0, 0.0, 0.0), e2=(0.0, 1.0, 0.0)):
    pose = Pose(magnet_position_m=(x_m, y_m, 0.0), theta0_rad=math.radians(theta0_deg), plane_e1=e1, plane_e2=e2)
    return PlacedProbe(P, pose)


# Three probes 4–6 cm apart, turned differently, one in a vertical plane.
TRIO = [placed(0.0, theta0_deg=30.0), placed(0.05, 0.01, 120.0), placed(0.02, 0.045, 200.0, e2=(0.0, 0.0, 1.0))]


def test_each_probe_feels_the_exact_dipoles_of_the_others_along_their_levers():
    state = coupled_rest(TRIO, NO_FIELD)
    for i, probe in enumerate(TRIO):
        x_axis, y_axis, _ = probe.pose.axes()
        angle = state.rest_angle_rad[i]
        # The moment follows the orientation: along the lever, turned by θ0 and the rest angle.
        assert state.moment_am2[i] == pytest.approx(
            P.moment_am2 * (math.cos(angle) * x_axis + math.sin(angle) * y_axis)
        )
        expected = sum(
            dipole(state.moment_am2[j], state.position_m[i] - state.position_m[j]) for j in range(3) if j != i
        )
        assert state.neighbour_field_t()[i] == pytest.approx(expected, rel=1e-12, abs=1e-21)


def test_neighbour_gradient_is_the_derivative_of_the_neighbour_field_and_obeys_maxwell():
    state = coupled_rest(TRIO, NO_FIELD)
    h = 1e-5
    for i in range(3):
        neighbours, at = state.neighbours(i), state.position_m[i]
        numeric = np.column_stack(
            [(neighbours.field_t(at + h * e) - neighbours.field_t(at - h * e)) / (2 * h) for e in np.eye(3)]
        )
        gradient = state.neighbour_gradient_t_per_m()[i]
        scale = np.linalg.norm(gradient)
        assert np.abs(gradient - numeric).max() < 1e-6 * scale  # central difference: ~10·(h/r)²
        assert np.abs(gradient - gradient.T).max() < 1e-12 * scale  # ∇×B = 0
        assert abs(np.trace(gradient)) < 1e-12 * scale  # ∇·B = 0
        assert abs(np.trace(numeric)) < 1e-6 * scale  # …and so for the finite difference itself


@pytest.mark.parametrize("theta0_deg, direction", [(0.0, (1, 0, 0)), (90.0, (0, 1, 0)), (0.0, (0, 0, 1))])
def test_coupling_falls_as_the_inverse_cube_and_its_gradient_as_the_fourth_power(theta0_deg, direction):
    # On the moment's axis, or across it out of the rotation plane, neither the field nor its
    # gradient turns the lever (mirror symmetry): the magnets stay where they are put and only
    # the distance changes.
    def at(distance_m):
        x, y, z = distance_m * np.array(direction, float)
        pose = Pose(magnet_position_m=(x, y, z), theta0_rad=math.radians(theta0_deg))
        state = coupled_rest([placed(0.0, theta0_deg=theta0_deg), PlacedProbe(P, pose)], NO_FIELD)
        return state.neighbour_field_t()[1], state.neighbour_gradient_t_per_m()[1]

    near, far = at(0.04), at(0.08)
    np.testing.assert_allclose(far[0], near[0] / 8, rtol=1e-10, atol=1e-12 * np.linalg.norm(near[0]))
    np.testing.assert_allclose(far[1], near[1] / 16, rtol=1e-10, atol=1e-12 * np.linalg.norm(near[1]))


def test_the_paper_moment_at_5_cm_gives_1p4_microtesla_and_a_few_millihertz():
    pair = [placed(0.0), placed(0.05)]  # coaxial, both along x: each on the other's axis
    state = coupled_rest(pair, NO_FIELD)
    field = state.neighbour_field_t()
    assert field[:, 0] == pytest.approx(2 * MU0_OVER_4PI * P.moment_am2 / 0.05**3, rel=1e-12)
    assert 1.40e-6 < field[0, 0] < 1.45e-6
    alone = ArcPotential.from_source(P, NO_FIELD, Pose()).frequency_hz()
    shift_hz = coupled_frequencies_hz(pair, NO_FIELD) - alone
    # The published model's k = kM + m·Bx' plus the lever's first-order terms m·l·(Gx'x' − 2Gy'y')
    # (docs/physics.md §4); the neglected ones are of order (l/r)² ≈ 1.5e-3 of the shift. The lever
    # makes the two shifts differ: one lever points at the other magnet, one away from it.
    gradient = state.neighbour_gradient_t_per_m()
    first_order = P.beta0_hz_per_t * (field[:, 0] + P.lever_m * (gradient[:, 0, 0] - 2 * gradient[:, 1, 1]))
    assert shift_hz == pytest.approx(first_order, rel=0.02)
    assert np.all((3e-3 < shift_hz) & (shift_hz < 8e-3))
    assert np.all(shift_hz > 10 * 0.33e-3)  # far above the probe's precision


def total_energy_j(angles, probes):
    """Σ ½kM·θ² − Σ_{i<j} m_i·B_j(r_i): the scene's energy (no field, gravity across the planes)."""
    moments, positions = magnets_at(probes, angles)
    energy = 0.5 * P.spring_nm_per_rad * np.sum(np.square(angles))
    for i in range(len(probes)):
        for j in range(i):
            energy -= moments[i] @ dipole(moments[j], positions[i] - positions[j])
    return energy


def test_coupled_rest_angles_are_the_minimum_of_the_total_energy():
    # 1 cm apart, each across the other's field: 3.4 mrad rest angles that turn each other.
    close = [placed(0.0), placed(0.0, 0.01), placed(0.012, 0.008, 60.0)]
    state = coupled_rest(close, NO_FIELD)
    h = 1e-6

    def torque(angles):
        steps = h * np.eye(len(angles))
        return [(total_energy_j(angles + s, close) - total_energy_j(angles - s, close)) / (2 * h) for s in steps]

    scale = P.spring_nm_per_rad
    minimum = optimize.root(lambda a: np.array(torque(a)) / scale, np.zeros(3), tol=1e-15).x
    assert np.abs(state.rest_angle_rad - minimum).max() < 1e-9
    # One pass (each in its neighbours' field at their unturned angles) misses it by far more.
    unturned = np.array([_rest_in_unturned_neighbours(close, i) for i in range(3)])
    assert np.abs(unturned - minimum).max() > 1e-6
    assert state.iterations > 2


def _rest_in_unturned_neighbours(probes, index):
    first = CoupledRest(np.zeros(len(probes)), *magnets_at(probes, np.zeros(len(probes))), 0)
    return float(ArcPotential.from_source(P, first.neighbours(index), probes[index].pose).rest_angle_rad())


def test_probes_too_close_or_missing_are_refused_by_name():
    too_close = r"probe 1 = \[0.002, 0.0, 0.0\] is 2.00 mm from probe 0 = \[0.0, 0.0, 0.0\]: .* more than 7.78 mm apart"
    with pytest.raises(ValueError, match=too_close):
        coupled_rest([placed(0.0), placed(0.002)], NO_FIELD)
    with pytest.raises(ValueError, match="at least one probe"):
        coupled_rest([], NO_FIELD)


# --- a buckled probe: beyond spring cancellation its rest is off zero ------------------------
# An axial field 2 % past −kM/m along x: the probe turned to 0° (moment along +x, against the
# field) buckles by ~20°; one turned to 180° (moment along the field) is stiffened.
BUCKLING = UniformField([1.02 * P.cancellation_field_t, 0.0, 0.0])


def exact_energy_j(angles, poses, scene_t):
    """Σ ½kM·θ² − Σ m_i·B_scene − Σ_{i<j} m_i·B_j(r_i) of magnets on levers in the xy plane,
    the geometry written out here: moment along (cos(θ0 + θ), sin(θ0 + θ)), magnet at
    pivot + l·that, the pivot l behind its rest position."""
    moments, positions = [], []
    for (x_m, y_m, theta0), angle in zip(poses, angles):
        rest_axis = np.array([math.cos(theta0), math.sin(theta0), 0.0])
        axis = np.array([math.cos(theta0 + angle), math.sin(theta0 + angle), 0.0])
        moments.append(P.moment_am2 * axis)
        positions.append(np.array([x_m, y_m, 0.0]) + P.lever_m * (axis - rest_axis))
    energy = 0.5 * P.spring_nm_per_rad * float(np.sum(np.square(angles)))
    for i in range(len(poses)):
        energy -= moments[i] @ np.asarray(scene_t)
        for j in range(i):
            energy -= moments[i] @ dipole(moments[j], positions[i] - positions[j])
    return energy


def test_a_lone_buckled_probe_rests_at_the_minimum_of_its_energy():
    state = coupled_rest([placed(0.0)], BUCKLING)
    field = BUCKLING.field_t(np.zeros(3))
    # U = ½kM·θ² − m·Bx·cos θ has two alike wells; the positive one is taken on the symmetric top.
    well = optimize.minimize_scalar(
        lambda a: exact_energy_j([a], [(0.0, 0.0, 0.0)], field),
        bounds=(1e-3, 0.7),
        method="bounded",
        options={"xatol": 1e-12},
    ).x
    assert math.radians(15.0) < well < math.radians(25.0)
    # Brent's minimum is good to √ε of the angle; the root of U' there to rounding.
    assert state.rest_angle_rad[0] == pytest.approx(well, abs=1e-7)
    torque_free = optimize.brentq(
        lambda a: P.spring_nm_per_rad * a + P.moment_am2 * field[0] * math.sin(a), well - 1e-3, well + 1e-3
    )
    assert state.rest_angle_rad[0] == pytest.approx(torque_free, abs=1e-12)


def test_two_probes_one_buckled_rest_at_the_minimum_of_the_total_energy():
    poses = [(0.0, 0.0, 0.0), (0.02, 0.025, math.pi)]
    pair = [placed(x, y, math.degrees(theta0)) for x, y, theta0 in poses]
    state = coupled_rest(pair, BUCKLING)
    field = BUCKLING.field_t(np.zeros(3))
    total = lambda angles: exact_energy_j(angles, poses, field)  # noqa: E731
    # The buckled probe falls to the side its neighbour's field pushes it from 0.
    h = 1e-7
    downhill = -np.sign(total([h, 0.0]) - total([-h, 0.0]))
    buckled, stiff = state.rest_angle_rad
    assert np.sign(buckled) == downhill and math.radians(15.0) < abs(buckled) < math.radians(25.0)
    assert abs(stiff) < 1e-3
    # The coupled rest is the minimum of the total energy, found from a start 0.1 rad away.
    found = optimize.minimize(
        total,
        state.rest_angle_rad + [0.1, -0.1],
        method="Nelder-Mead",
        options={"xatol": 1e-12, "fatol": 1e-30, "maxiter": 20_000},
    ).x
    assert np.abs(state.rest_angle_rad - found).max() < 1e-7
    # Each probe's rest is the minimum of its own exact energy with the other held where it rests.
    for k, bounds in ((0, sorted([downhill * 1e-3, downhill * 0.7])), (1, (-0.3, 0.3))):
        alone = optimize.minimize_scalar(
            lambda a, k=k: total(np.where(np.arange(2) == k, a, state.rest_angle_rad)),
            bounds=bounds,
            method="bounded",
            options={"xatol": 1e-12},
        ).x
        assert state.rest_angle_rad[k] == pytest.approx(alone, abs=1e-7)  # √ε of Brent's minimum
