"""Several probes integrated together by the simulated device, against solve_ivp and the coupled
first-principles model.

Requirements: the RK4 integration of the coupled equations of motion agrees with an independent
integrator (scipy's DOP853 at tight tolerances) and converges at fourth order; the ring-down
frequencies it produces are those of each probe in its neighbours' static field
(:func:`mows.physics.coupling.coupled_frequencies_hz`), the swing of the neighbours at their
own, different frequencies adding no shift beyond a small fraction of the coupling's.
"""

import math

import numpy as np
import pytest
from scipy import integrate

from mows.physics.coupling import PlacedProbe, coupled_frequencies_hz
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.physics.sources import UniformField
from scenes import scene_device

NO_FIELD = UniformField([0.0, 0.0, 0.0])
STIFFER = P.replace(spring_nm_per_rad=P.spring_nm_per_rad * 1.24)  # f00 ≈ 125 Hz
RATE_HZ = 10_000.0


def crossing_frequency_hz(theta, rate_hz):
    """Frequency from a line through the zero-crossing times (exactly periodic for a damped sine)."""
    k = np.flatnonzero(np.sign(theta[:-1]) != np.sign(theta[1:]))
    times = (k + theta[k] / (theta[k] - theta[k + 1])) / rate_hz
    return 0.5 / np.polyfit(np.arange(times.size), times, 1)[0]


def test_rk4_agrees_with_solve_ivp_and_converges_at_fourth_order():
    # 1 cm apart, across each other's axes, large swings: strong, nonlinear coupling.
    close = [PlacedProbe(P, Pose()), PlacedProbe(STIFFER, Pose(magnet_position_m=(0.0, 0.01, 0.0), theta0_rad=0.4))]
    start, n = [0.17, -0.09], 500
    times = np.arange(n) / RATE_HZ
    reference = (
        integrate.solve_ivp(
            scene_device(close, sample_rate_hz=RATE_HZ).equation_of_motion(),
            (0.0, times[-1]),
            np.r_[start, 0.0, 0.0],
            method="DOP853",
            rtol=1e-12,
            atol=1e-14,
            t_eval=times,
        )
        .y[:2]
        .T
    )
    errors = [
        np.abs(scene_device(close, sample_rate_hz=RATE_HZ, substeps=substeps).ring_down(start, n)[0] - reference).max()
        for substeps in (2, 4)
    ]
    assert errors[0] < 3e-7  # rad, over 6 periods of a 10° swing
    assert errors[0] / errors[1] > 10  # 2⁴ = 16 for a fourth-order method


def test_the_coupling_torque_is_the_derivative_of_the_interaction_energy():
    close = [PlacedProbe(P, Pose()), PlacedProbe(STIFFER, Pose(magnet_position_m=(0.004, 0.008, 0.002)))]
    probes = scene_device(close, sample_rate_hz=RATE_HZ)
    theta, h = np.array([0.2, -0.3]), 1e-6

    def interaction_j(angles):
        # −m_0·B_1(r_0) with the dipole field written out: one pair, counted once.
        directions = [p.pose.moment_direction_at(a) for p, a in zip(close, angles)]
        positions = [p.pose.magnet_position_at(a, p.probe.lever_m) for p, a in zip(close, angles)]
        m0, m1 = P.moment_am2 * directions[0], STIFFER.moment_am2 * directions[1]
        r = positions[0] - positions[1]
        unit = r / np.linalg.norm(r)
        return -1e-7 * (3 * (m0 @ unit) * (m1 @ unit) - m0 @ m1) / np.linalg.norm(r) ** 3

    for i in range(2):
        step = h * np.eye(2)[i]
        numeric = -(interaction_j(theta + step) - interaction_j(theta - step)) / (2 * h)
        assert probes.coupling_torque_nm(theta)[i] == pytest.approx(numeric, rel=1e-6)


def test_simulated_frequencies_are_the_coupled_model_s():
    # The paper's probe and a stiffer one 5 cm apart on a common axis: 6.5 and 3.7 mHz shifts.
    pair = [PlacedProbe(P, Pose()), PlacedProbe(STIFFER, Pose(magnet_position_m=(0.05, 0.0, 0.0)))]
    theta, _ = scene_device(pair, sample_rate_hz=RATE_HZ).ring_down([math.radians(1.0)] * 2, 3000)
    simulated = np.array([crossing_frequency_hz(theta[:, i], RATE_HZ) for i in range(2)])
    model = coupled_frequencies_hz(pair, NO_FIELD)
    alone = np.array([float(ArcPotential.from_source(p.probe, NO_FIELD, p.pose).frequency_hz()) for p in pair])
    assert np.all(model - alone > 3e-3)  # the coupling the simulation must reproduce
    assert np.abs(simulated - model).max() < 1e-4  # Hz: within 3 % of the smaller shift
    assert simulated - alone == pytest.approx(model - alone, rel=0.03)


def test_bad_starts_are_refused_by_value():
    probes = scene_device([PlacedProbe(P, Pose()), PlacedProbe(P, Pose(magnet_position_m=(0.05, 0, 0)))])
    with pytest.raises(ValueError, match=r"start_rad = \[0.1\] must give one deflection per probe \(2\)"):
        probes.ring_down([0.1], 10)
    with pytest.raises(ValueError, match="n_samples = 0"):
        probes.ring_down([0.1, 0.1], 0)
