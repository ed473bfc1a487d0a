"""Each probe's external field and gradient from a sweep of three probes, the coupling in the model.

Requirement (docs/multi_probe.md): a sweep of the three_probes scene (shared stage, 8 points,
simulated in device time: multi-tone excitation, joint fits) decomposes every probe's in-plane
B and G to the scene's field at that probe within its σ, with the neighbours' dipole fields and
the field's 3θ0 curvature part of the first-principles model; leaving the coupling out is
biased by many σ.

What a sweep determines is the field at the magnet's rest position (the stage's axis) plus
(l²/4)·∂²(Bx, By)/∂z², the part of the field's curvature over the lever's arc that turns with
θ0 as the field does (mows.sweep.shift_model). It is −39 to +72 nT at these probes, 0.5–1.7σ of
one sweep, so the truth is taken with it; the field at the magnet alone is the stated limit
(docs/multi_probe.md). Seeds 1–4, 60 components: 58 within 2σ, the largest 2.30σ, mean z² 0.64
(a calibrated σ puts 57 ± 1.6 of 60 within 2σ); against the field at the magnet alone probe
2's Bx is 0.7–2.9σ high, 2.0σ on average.
"""

import numpy as np
import pytest

from mows.bench.rig import ONE_ROUND, DeviceTimeRig
from mows.device.cycle.phases import CycleRequest
from mows.physics.coupling import coupled_rest
from mows.physics.sources import LinearGradient
from mows.sim.scenario import load_scenario
from mows.sim.sections import Environment
from mows.sweep.probes import ProbeSweep, decompose_probes, neighbour_fields, sweeps_of
from mows.sweep.record import SweepPoint, SweepRecord

# One worker runs the whole module, so that its module fixture (18 s of simulation) is computed
# once, not once per xdist worker.
pytestmark = pytest.mark.xdist_group("multiprobe_sweep")

SCENE = load_scenario("three_probes")
POINTS = 8


SEEDS = (1, 2, 3, 4)
STEP_M = 1e-3  # central differences of a field smooth over centimetres


def truth(placed, scene=SCENE, sweepable=True):
    """(Bx, By, Gxx, Gxy, Gyy) of the scene's field at the probe's magnet; with ``sweepable``
    the field plus (l²/4)·∂²(Bx, By)/∂z² there (the module docstring), by central differences."""
    source = scene.environment.source
    where = np.asarray(placed.pose.magnet_position_m, float)
    field, gradient = source.field_t(where), source.gradient_t_per_m(where)
    if sweepable:
        up = np.array([0.0, 0.0, STEP_M])
        curvature = (source.field_t(where + up) - 2.0 * field + source.field_t(where - up)) / STEP_M**2
        field = field + placed.probe.lever_m**2 / 4.0 * curvature
    return np.r_[field[:2], gradient[0, 0], gradient[0, 1], gradient[1, 1]]


def z_scores(decompositions, scene=SCENE, sweepable=True):
    """(probes, 5): each component's error against the truth in its own σ."""
    rows = []
    for placed, d in zip(scene.placed_probes(), decompositions):
        assert d.ok, d.message
        sigma = np.sqrt(np.r_[np.diag(d.field_covariance_t2), np.diag(d.gradient_covariance)])
        rows.append((np.r_[d.field_t, d.gradient_t_per_m] - truth(placed, scene, sweepable)) / sigma)
    return np.array(rows)


def sweep(scene, seed=2):
    rig = DeviceTimeRig(scene, ONE_ROUND, seed=seed)
    points = [rig.run_cycle(CycleRequest(2 * np.pi * j / POINTS)).fits for j in range(POINTS)]
    return sweeps_of(scene.placed_probes(), points, scene.sensors.pair)


@pytest.fixture(scope="module")
def seeded():
    """Each seed's sweeps and their coupled decompositions."""
    return {seed: (s := sweep(SCENE, seed), decompose_probes(s)) for seed in SEEDS}


@pytest.fixture(scope="module")
def sweeps(seeded):
    return seeded[2][0]


@pytest.fixture(scope="module")
def coupled(seeded):
    return z_scores(seeded[2][1])


@pytest.mark.slow
def test_the_sweep_keeps_every_point_and_finds_each_probes_swing(sweeps):
    for sweep in sweeps:
        assert len(sweep.theta0_rad) == POINTS
        start_swing_rad = np.array([p.amplitude_rad for p in sweep.record.points])
        assert np.all((start_swing_rad > 0.05) & (start_swing_rad < 0.3))


@pytest.mark.slow
def test_with_the_coupling_every_probes_field_and_gradient_lie_within_their_sigma(seeded):
    z = np.array([z_scores(decompositions) for _, decompositions in seeded.values()])
    print("z with the coupling (seed, probe; Bx, By, Gxx, Gxy, Gyy):\n", np.round(z, 2))
    # Bounds for 60 calibrated z-scores, each ~3.5 standard errors from what N(0, 1) gives:
    # mean z² 1 ± 0.18, within 2σ 95.4 ± 2.7 %, and P(any |z| > 3.5) = 3 %.
    assert np.mean(z**2) < 1.6  # 0.64 measured
    assert np.mean(np.abs(z) < 2.0) > 0.85  # 58 of 60 measured
    assert np.abs(z).max() < 3.5  # 2.30 measured


@pytest.mark.slow
def test_the_field_at_the_magnet_alone_misses_the_curvature_no_sweep_separates(seeded):
    # Probe 2 sits where (l²/4)·∂²Bx/∂z² is +72 nT, 1–1.7σ of one sweep.
    z = np.array([z_scores(decompositions, sweepable=False)[2, 0] for _, decompositions in seeded.values()])
    print("probe 2's Bx against the field at its magnet, z per seed:", np.round(z, 2))
    assert np.mean(z) > 1.5  # 2.0 measured


@pytest.mark.slow
def test_leaving_the_coupling_out_is_biased_by_many_sigma(sweeps, coupled):
    alone = z_scores(decompose_probes(sweeps, coupling=False))
    print("z without the coupling:\n", np.round(alone, 2))
    assert np.abs(alone).max() > 8.0  # 58.9 measured (probe 1's Gxy)
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
    coupled = decompose_probes(sweeps)  # the curvature is fitted though the field has none
    with_coupling, alone = z_scores(coupled, linear), z_scores(decompose_probes(sweeps, coupling=False), linear)
    print("z with and without the coupling:\n", np.round(with_coupling, 2), "\n", np.round(alone, 2))
    assert np.abs(with_coupling).max() < 2.5  # 2.28 measured, 15 components
    # 1 degree of freedom (8 points, 7 unknowns): 9 is χ²'s 99.7 % point there
    assert max(d.chi2_dof for d in coupled) < 9.0  # 0.05–0.8 measured
    assert np.abs(alone).max() > 6.0  # 59.5 measured


def one_point(theta0_rad, f00_hz):
    """A record of one ring-down at ``theta0_rad``, where only its θ0 counts."""
    return SweepRecord([SweepPoint(theta0_rad, f00_hz, 1.0, 0.0, 1.0, np.nan, np.nan, np.nan, 0.0)])


def test_the_neighbour_fields_are_those_of_the_coupled_rest():
    # From the scene's own fields at each probe (its linear part), the decomposition's model
    # of the neighbours reproduces the coupled rest state of mows.physics.coupling.
    placed = SCENE.placed_probes()
    home = np.array([[p.pose.theta0_rad] for p in placed])
    sweeps = [
        ProbeSweep(k, p, one_point(home[k][0], p.probe.f00_hz), p.probe.f00_hz, np.arange(1))
        for k, p in enumerate(placed)
    ]
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
