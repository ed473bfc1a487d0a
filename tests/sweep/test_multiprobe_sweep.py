"""Each probe's external field and gradient from a sweep of three probes, the coupling in the model.

Requirement (docs/multi_probe.md): a sweep of the three_probes scene (shared stage, 8 points,
simulated in device time: multi-tone excitation, joint fits) decomposes every probe's in-plane
B and G within 2σ of the scene's field at that probe, with the neighbours' dipole fields part
of the first-principles model; leaving them out is biased by many σ.

Measured over seeds 1–4 (the same sweep): with the coupling, 13 of the 15 components lie within
2σ in every seed; probe 0's field does not: its (Bx, By) come out (1.1, 1.8), (2.9, 4.1),
(2.8, 3.7) and (2.3, 2.7)σ high, about +0.2 µT. That part of the requirement is not met (the
strict xfail below says so and will flag the fix); its cause is not found. A noise-free sweep
of exact static physics decomposes probe 0's field within 0.04 µT, so it is not the coupling's
static model; pickups turned to the true rest angles move the pulls by < 0.1σ, so it is not the
joint fit's missing rest offset (docs/multi_probe.md). Without the coupling, probe 0's gradient
is off by 10–14σ.
"""

import numpy as np
import pytest

from mows.bench.multiprobe_rig import MultiProbeRig
from mows.physics.coupling import coupled_rest
from mows.sim.scenario import load_scenario
from mows.sweep.multiprobe import ProbeSweep, decompose_probes, neighbour_fields, sweeps_of

SCENE = load_scenario("three_probes")
POINTS = 8


def truth(placed):
    """(Bx, By, Gxx, Gxy, Gyy) of the scene's field at the probe's magnet."""
    where = np.asarray(placed.pose.magnet_position_m, float)
    field, gradient = SCENE.environment.source.field_t(where), SCENE.environment.source.gradient_t_per_m(where)
    return np.r_[field[:2], gradient[0, 0], gradient[0, 1], gradient[1, 1]]


def z_scores(decompositions):
    """(probes, 5): each component's error against the truth in its own σ."""
    rows = []
    for placed, d in zip(SCENE.placed_probes(), decompositions):
        assert d.ok, d.message
        sigma = np.sqrt(np.r_[np.diag(d.field_covariance_t2), np.diag(d.gradient_covariance)])
        rows.append((np.r_[d.field_t, d.gradient_t_per_m] - truth(placed)) / sigma)
    return np.array(rows)


@pytest.fixture(scope="module")
def sweeps():
    rig = MultiProbeRig(SCENE, seed=2)
    points = [rig.run_cycle(rig.home_orientations_rad() + 2 * np.pi * j / POINTS).fits for j in range(POINTS)]
    return sweeps_of(SCENE.placed_probes(), points, SCENE.sensors.pair)


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
@pytest.mark.xfail(strict=True, reason="probe 0's field is biased by about +0.2 µT (1.1–4.1σ over four seeds)")
def test_with_the_coupling_probe_0s_field_lies_within_two_sigma(coupled):
    assert np.all(np.abs(coupled[0, :2]) < 2.0)


@pytest.mark.slow
def test_leaving_the_coupling_out_is_biased_by_many_sigma(sweeps, coupled):
    alone = z_scores(decompose_probes(sweeps, coupling=False))
    print("z without the coupling:\n", np.round(alone, 2))
    assert np.abs(alone).max() > 8.0  # 14.1 measured (probe 0's Gxy)
    assert np.sum(alone**2) > 5.0 * np.sum(coupled**2)


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
