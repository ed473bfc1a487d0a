"""The model lab on one finished sweep, as the mapper runs it live (mows.lab.analyse_sweep).

Requirement: a sweep of ring-downs at the first-principles frequencies of the scene's field
(the anti-Helmholtz pair plus the Earth's field at the probe), each the harmonic-balance
frequency averaged over its decaying swing as a constant-frequency fit reports it
(mows.physics.ringdown_average), with σ = 0.5 mHz of noise, is
read in that scene as the reference: every ring-down is a row, and the published model plus
what the lab adds describes it to within the noise (χ²/dof below 2: the 99.9 % point for 15
degrees of freedom is 2.5). A sweep without ring-downs raises ValueError, which the node logs.
"""

import math

import numpy as np
import pytest

from mows.lab import analyse_sweep
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.ringdown_average import amplitude_nodes
from mows.sim.scenario import load_scenario
from mows.sweep.decomposition import Decomposition, DecompositionStatus
from mows.sweep.events import SweepMap
from mows.sweep.record import SweepPoint, SweepRecord

STD_HZ, DURATION_S = 5e-4, 0.5
SCENE = load_scenario("anti_helmholtz")
P = SCENE.probe


def sweep(rng):
    points = []
    for theta0 in np.radians(np.arange(0.0, 360.0, 45.0)).repeat(2):
        pose = Pose(theta0_rad=theta0, magnet_position_m=SCENE.pose.magnet_position_m)
        potential = ArcPotential.from_source(P, SCENE.environment.source, pose)
        start = float(potential.start_swing_rad(P.theta_stop_rad))
        amplitudes, weights = amplitude_nodes(theta0, start, P.damping_per_s, DURATION_S)
        f = sum(c * float(potential.frequency_hz(a)) for a, c in zip(amplitudes[0], weights[0]))
        f += STD_HZ * rng.standard_normal()
        points.append(SweepPoint(theta0, f, STD_HZ, f - P.f00_hz, STD_HZ, start, P.damping_per_s, DURATION_S, 0.0))
    record = SweepRecord(points)
    return SweepMap(1, record.decompose(P, P.f00_hz), record, P.f00_hz)


def test_a_sweep_in_its_reference_is_described_to_within_its_noise():
    report = analyse_sweep(sweep(np.random.default_rng(2)), "anti_helmholtz", P, auto=True)
    assert report.n == 16 and math.isfinite(report.chi2_dof) and report.chi2_dof < 2.0, report.chi2_dof


def test_a_sweep_without_ring_downs_is_a_value_error():
    empty = Decomposition("first_principles", DecompositionStatus.NO_DECOMPOSITION, "no ring-down")
    with pytest.raises(ValueError):
        analyse_sweep(SweepMap(1, empty, SweepRecord(), P.f00_hz), "anti_helmholtz", P)
