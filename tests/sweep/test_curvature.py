"""The field's curvature over the lever's arc in a rotation sweep.

Requirement (mows.sweep.decompose, docs/multi_probe.md): in a curved field the decomposition
with ``curvature`` fits the curvature's 3θ0 part, so that unequal σ over the sweep no longer
leak it into B, and what it reports for B is the field at the magnet's rest position plus the
1θ0 part no sweep can separate, (l²/4)·∂²(Bx, By)/∂z². The frequencies are the exact
first-principles ones in the anti-Helmholtz pair's field at the three_probes scene's places
(2.9 cm off its centre), without noise; the curvature is checked against finite differences of
that field, not against the decomposition's own model.
"""

import numpy as np
import pytest

from mows.physics.potential import ArcPotential
from mows.sim.scenario import load_scenario
from mows.sweep.decompose import decompose
from mows.sweep.decomposition import DecompositionStatus
from mows.sweep.shift_model import curvature_hessian_t_per_m2

SCENE = load_scenario("three_probes")
SOURCE = SCENE.environment.source
STEP_M = 1e-3  # the field is smooth over centimetres: FD error ~ (1 mm / 10 cm)² of ∂²B
# The sweep's σ spread as the multi-tone sweeps' (0.04–1.7 mHz), fixed so the test is repeatable.
STD_HZ = np.array([4e-5, 1.7e-3, 3e-4, 9e-5, 1.2e-3, 6e-5, 6e-4, 2e-4])


def exact_sweep(placed):
    theta0 = placed.pose.theta0_rad + 2 * np.pi * np.arange(STD_HZ.size) / STD_HZ.size
    probe = placed.probe
    stiffness = np.array(
        [ArcPotential.from_source(probe, SOURCE, placed.pose.with_theta0(t)).stiffness_nm_per_rad() for t in theta0]
    ).ravel()
    return theta0, probe.f00_hz * np.sqrt(stiffness / probe.spring_nm_per_rad) - probe.f00_hz


def second_derivatives(where):
    """H[i, j, k] = ∂²B_i/∂x_j∂x_k by central differences of the field itself."""
    hessian = np.empty((3, 3, 3))
    for j, k in np.ndindex(3, 3):
        ej, ek = np.eye(3)[j] * STEP_M, np.eye(3)[k] * STEP_M
        corners = [SOURCE.field_t(where + sj * ej + sk * ek) * sj * sk for sj in (1, -1) for sk in (1, -1)]
        hessian[:, j, k] = np.sum(corners, axis=0) / (4 * STEP_M**2)
    return hessian


@pytest.mark.parametrize("index", range(3))
def test_the_curvature_is_fitted_and_the_field_keeps_only_its_inseparable_part(index):
    placed = SCENE.placed_probes()[index]
    theta0, shift = exact_sweep(placed)
    where = np.asarray(placed.pose.magnet_position_m, float)
    h = second_derivatives(where)
    lever = placed.probe.lever_m
    inseparable = lever**2 / 4 * h[:2, 2, 2]
    curved = decompose(theta0, shift, STD_HZ, placed.probe, placed.probe.f00_hz, curvature=True)
    linear = decompose(theta0, shift, STD_HZ, placed.probe, placed.probe.f00_hz)
    sweepable = SOURCE.field_t(where)[:2] + inseparable  # 39–72 nT from the field at the magnet
    assert np.abs(curved.field_t - sweepable).max() < 0.1e-9  # 0.03 nT measured
    assert np.abs(linear.field_t - sweepable).max() > 30e-9  # 37–95 nT measured: the 3θ0 term leaks
    # Hc, Hs: the in-plane harmonic part of ∂²B_i/∂x_j∂x_k, the trace part taken out.
    expected = [(h[0, 0, 0] - 3 * h[0, 1, 1]) / 4, (3 * h[0, 0, 1] - h[1, 1, 1]) / 4]
    assert np.allclose(curved.parameters[6:], expected, rtol=0.005, atol=1e-4)
    assert curved.rms_residual_hz < 1e-5 < 1e-4 < linear.rms_residual_hz


def test_the_curvature_tensor_is_that_of_a_harmonic_potential():
    hessian = curvature_hessian_t_per_m2(0.3, -0.2)
    assert np.allclose(hessian, np.transpose(hessian, (1, 0, 2))) and np.allclose(
        hessian, np.transpose(hessian, (0, 2, 1))
    )
    assert np.allclose(np.einsum("ijj->i", hessian), 0.0)  # ∇²B = 0


def test_the_curvature_needs_seven_orientations():
    placed = SCENE.placed_probes()[0]
    theta0, shift = exact_sweep(placed)
    six = np.r_[0:3, 4:7]
    d = decompose(theta0[six], shift[six], STD_HZ[six], placed.probe, placed.probe.f00_hz, curvature=True)
    assert d.status is DecompositionStatus.TOO_FEW_ORIENTATIONS and "need at least 7" in d.message
