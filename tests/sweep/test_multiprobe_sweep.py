"""Each probe's external field and gradient from a sweep of three probes, the coupling in the model.

Requirement (docs/multi_probe.md): a sweep of the three_probes scene (shared stage, 8 points,
simulated in device time: multi-tone excitation, joint fits) decomposes every probe's in-plane
B and G within 2σ of the scene's field at that probe, with the neighbours' dipole fields part
of the first-principles model; leaving them out is biased by many σ.

Measured over seeds 1–4 (the same sweep): with the coupling, 13 of the 15 components lie within
2σ in every seed; probe 0's field does not: its (Bx, By) come out (1.1, 1.8), (2.9, 4.1),
(2.8, 3.7) and (2.3, 2.7)σ high, about +0.2 µT. That part of the requirement is not met in
this scene (the strict xfail below says so and will flag the fix). The cause is the
anti-Helmholtz field's curvature over the swinging lever, which the decomposition's linear
field leaves out: the same sweep in a field of the same gradient without curvature puts probe
0's field at (0.08, 0.12)σ and every component within 2.06σ (docs/multi_probe.md). Without
the coupling, probe 0's gradient is off by 10–14σ.
"""

import numpy as np
import pytest

from mows.bench.multiprobe_rig import MultiProbeRig
from mows.physics.coupling import coupled_rest
from mows.physics.sources import LinearGradient
from mows.sim.scenario import load_scenario
from mows.sim.sections import Environment
from mows.sweep.multiprobe import ProbeSweep, decompose_probes, neighbour_fields, sweeps_of

SCENE = load_scenario("three_probes")
POINTS = 8


def truth(placed, scene=SCENE):
    """(Bx, By, Gxx, Gxy, Gyy) of the scene's field at the probe's magnet."""
    where = np.asarray(placed.pose.magnet_position_m, float)
    field, gradient = scene.environment.source.field_t(where), scene.environment.source.gradient_t_per_m(where)
    return np.r_[field[:2], gradient[0, 0], gradient[0, 1], gradient[1, 1]]


def z_scores(decompositions, scene=SCENE):
    """(probes, 5): each component's error against the truth in its own σ."""
    rows = []
    for placed, d in zip(scene.placed_probes(), decompositions):
        assert d.ok, d.message
        sigma = np.sqrt(np.r_[np.diag(d.field_covariance_t2), np.diag(d.gradient_covariance)])
        rows.append((np.r_[d.field_t, d.gradient_t_per_m] - truth(placed, scene)) / sigma)
    return np.array(rows)


def sweep(scene):
    rig = MultiProbeRig(scene, seed=2)
    points = [rig.run_cycle(rig.home_orientations_rad() + 2 * np.pi * j / POINTS).fits for j in range(POINTS)]
    return sweeps_of(scene.placed_probes(), points, scene.sensors.pair)


@pytest.fixture(scope="module")
def sweeps():
    return sweep(SCENE)


@pytest.fixture(scope="module")
def coupled(sweeps):
    return z_scores(decompose_probes(sweeps))


@pytest.mark.slow
def test_the_sweep_keeps_every_point_and_finds_each_probes_swing(sweeps):
    for sweep in sweeps:
        assert len(sweep.theta0_rad) == POINTS
        assert np.all((sweep.ringdowns.start_swing_rad > 0.05) & (sweep.ringdowns.start_swing_rad < 0.3))


@pytest.mark.slow
def test_with_the_coupling_the_gradients_and_the_other_fields_lie_within_two_sigma(coupled):
    print("z with the coupling (Bx, By, Gxx, Gxy, Gyy):\n", np.round(coupled, 2))
    assert np.all(np.abs(coupled[:, 2:]) < 2.0)
    assert np.all(np.abs(coupled[1:, :2]) < 2.0)


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True, reason="the field's curvature, not in the model, biases probe 0's field by ~0.2 µT (1.1–4.1σ)"
)
def test_with_the_coupling_probe_0s_field_lies_within_two_sigma(coupled):
    assert np.all(np.abs(coupled[0, :2]) < 2.0)


@pytest.mark.slow
def test_leaving_the_coupling_out_is_biased_by_many_sigma(sweeps, coupled):
    alone = z_scores(decompose_probes(sweeps, coupling=False))
    print("z without the coupling:\n", np.round(alone, 2))
    assert np.abs(alone).max() > 8.0  # 14.1 measured (probe 0's Gxy)
    assert np.sum(alone**2) > 5.0 * np.sum(coupled**2)


@pytest.mark.slow
def test_in_a_field_without_curvature_the_coupled_decomposition_is_unbiased():
    # The scene's gradient at the coils' centre, exactly linear, and the Earth's field: the
    # decomposition's model is then exact but for the coupling.
    gradient = SCENE.environment.source.gradient_t_per_m(np.zeros(3))
    linear = SCENE.replace(
        environment=Environment((SCENE.environment.sources[0], LinearGradient(gradient, (0.0, 0.0, 0.0))))
    )
    sweeps = sweep(linear)
    coupled = decompose_probes(sweeps)
    with_coupling, alone = z_scores(coupled, linear), z_scores(decompose_probes(sweeps, coupling=False), linear)
    print("z with and without the coupling:\n", np.round(with_coupling, 2), "\n", np.round(alone, 2))
    assert np.abs(with_coupling).max() < 2.5  # 2.06 measured, 15 components
    assert max(d.chi2_dof for d in coupled) < 4.0  # 0.6–2.5 measured
    assert np.abs(alone).max() > 6.0  # 10.3 measured


def test_the_neighbour_fields_are_those_of_the_coupled_rest():
    # From the scene's own fields at each probe (its linear part), the decomposition's model
    # of the neighbours reproduces the coupled rest state of mows.physics.coupling.
    placed = SCENE.placed_probes()
    home = np.array([[p.pose.theta0_rad] for p in placed])
    sweeps = [ProbeSweep(p, p.probe.f00_hz, home[k], np.zeros(1), np.ones(1)) for k, p in enumerate(placed)]
    parameters = []
    for p in placed:
        bx, by, gxx, gxy, gyy = truth(p)
        parameters.append(np.array([bx, by, (gxx + gyy) / 2, (gxx - gyy) / 2, gxy, 0.0]))
    fields = neighbour_fields(sweeps, parameters)
    state = coupled_rest(placed, SCENE.environment.source)
    for k, f in enumerate(fields):
        # at the magnet's undeflected position, about which the model expands the field
        where = np.asarray(placed[k].pose.magnet_position_m, float)
        expected = state.neighbours(k).field_t(where)
        assert np.linalg.norm(f.field_t[0] - expected) < 1e-3 * np.linalg.norm(expected)
        gradient = state.neighbours(k).gradient_t_per_m(where)
        assert np.abs(f.gradient_t_per_m[0] - gradient).max() < 1e-3 * np.abs(gradient).max()
