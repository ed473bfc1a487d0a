"""A sweep's reported B and G are the readout's function of the field at its pose: the probe's
full potential in a field from Biot–Savart (the eight-coil system), decomposed by the sweep's
own code, agrees with the readout (in-plane B + gravity's field + the lever's curvature term,
in-plane G) to a fraction of the decomposition's σ in B; without the two known terms it does not."""

import numpy as np

from mows.physics.probe import PAPER_PROBE
from mows.sim.navigation import navigation_system
from mows.sweep.decompose import decompose
from mows.workspace.design import random_rotation
from mows.workspace.observations import gravity_field_t, plane_readout
from mows.workspace.simulated import GRAVITY_M_PER_S2, SweepPose, sweep_shifts_hz


def test_the_readout_predicts_what_the_sweep_decomposes():
    source = navigation_system(1.5e-3)
    rng = np.random.default_rng(11)
    pose = SweepPose(np.array([0.012, -0.008, 0.015]), random_rotation(rng)[:2])
    theta0 = np.arange(10) * (2 * np.pi / 10)
    shift = sweep_shifts_hz(source, pose, PAPER_PROBE, theta0)  # noise-free: σ are the fit's scale only
    sweep = decompose(theta0, shift, np.full(10, 0.75e-3), PAPER_PROBE, PAPER_PROBE.f00_hz, curvature=True)
    field_std = np.sqrt(np.diag(sweep.field_covariance_t2))
    position = pose.position_m
    gradient, hessian = source.gradient_t_per_m(position), source.hessian_t_per_m2(position)

    def read(lever_m, gravity):
        readout = plane_readout(pose.plane, lever_m, gravity_field_t(PAPER_PROBE, gravity))
        return (
            readout.field @ source.field_t(position)
            + np.einsum("pij,ij->p", readout.gradient, gradient)
            + np.einsum("pijk,ijk->p", readout.hessian, hessian)
            + readout.offset
        )

    expected = read(PAPER_PROBE.lever_m, GRAVITY_M_PER_S2)
    assert np.all(np.abs(sweep.field_t - expected[:2]) < 0.2 * field_std)
    without_curvature = read(0.0, GRAVITY_M_PER_S2)
    without_gravity = read(PAPER_PROBE.lever_m, (0.0, 0.0, 0.0))
    assert np.max(np.abs(sweep.field_t - without_curvature[:2]) / field_std) > 2
    assert np.max(np.abs(sweep.field_t - without_gravity[:2]) / field_std) > 100
    gradient_std = np.sqrt(np.diag(sweep.gradient_covariance))
    assert np.all(np.abs(sweep.gradient_t_per_m - expected[2:]) < 5 * gradient_std)
