"""Two probes ringing down together, seen by one fluxgate pair, fitted jointly.

Requirement: the coupled simulation, the exact dipole pickup of both swinging magnets and the
joint fit with each probe's lever-aware pickup recover each probe's frequency in its
neighbour's field (the coupled first-principles model) within the fit's uncertainty, and see
the coupling's shift, many σ away from the frequency the probe would have alone.
"""

import math

import numpy as np
import pytest

from mows.estimate.ringdown import ProbeLine, fit_ringdowns, swing_from_signal_rad
from mows.physics.coupling import PlacedProbe, coupled_frequencies_hz
from mows.physics.fluxgate import FluxgatePair, pickup_harmonics, pickup_scale_t
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.physics.sources import UniformField
from mows.sim.readings import swinging_pickup_t
from scenes import scene_device

RATE_HZ = 10_000.0
NO_FIELD = UniformField([0.0, 0.0, 0.0])


def ringing_together(start_rad, seed):
    """The paper's probe before the paper's pair and a 125 Hz probe 3 cm beside it, both along x,
    ringing down together from ``start_rad``: the pair, the probes and 0.5 s of the pair's
    samples with 0.1 nT of noise."""
    pair = FluxgatePair.paper()
    probes = [
        PlacedProbe(P, Pose()),
        PlacedProbe(P.replace(spring_nm_per_rad=P.spring_nm_per_rad * 1.24), Pose(magnet_position_m=(0.0, 0.03, 0.0))),
    ]
    theta, _ = scene_device(probes, sample_rate_hz=RATE_HZ).ring_down(start_rad, 5000)
    pickup = swinging_pickup_t(pair, probes, theta)
    return pair, probes, pickup + 1e-10 * np.random.default_rng(seed).standard_normal(pickup.shape)


def lines_of(pair, probes):
    """Each probe's line for the joint fit: its lever-aware pickup on its absolute scale, looked
    for at its coupled frequency to the nearest hertz."""
    return [
        ProbeLine(
            probe_id=k,
            theta0_rad=0.0,
            expected_frequency_hz=round(float(f)),
            pickup=tuple(pickup_harmonics(pair, p.pose, p.probe.lever_m, p.probe.moment_am2)),
            pickup_scale_t=pickup_scale_t(pair, p.pose.magnet_position_m, p.probe.moment_am2),
        )
        for k, (p, f) in enumerate(zip(probes, coupled_frequencies_hz(probes, NO_FIELD)))
    ]


def test_the_joint_fit_of_two_simulated_probes_sees_their_coupled_frequencies():
    # The coupling shifts them by −11.5 and −10.3 mHz.
    pair, probes, samples = ringing_together([math.radians(10.0), math.radians(12.0)], seed=2)
    model = coupled_frequencies_hz(probes, NO_FIELD)
    lines = lines_of(pair, probes)
    fits = fit_ringdowns(samples, RATE_HZ, lines)
    alone = np.array([float(ArcPotential.from_source(p.probe, NO_FIELD, p.pose).frequency_hz()) for p in probes])
    for fit, expected, uncoupled in zip(fits, model, alone):
        assert fit.ok, fit.message
        assert fit.chi2_dof < 1.2  # the joint model describes the two swinging magnets
        assert abs(fit.frequency_hz - expected) < 4 * fit.frequency_std_hz, (fit.frequency_hz, expected)
        assert abs(fit.frequency_hz - uncoupled) > 10 * fit.frequency_std_hz  # the coupling is seen


def test_each_swing_comes_from_its_signals_size_through_the_absolute_pickup():
    # Small swings, where a joint fit's signal shape barely fixes θmax: its size still does,
    # through the pickup's absolute scale (the dipole's μ0·m/4π over the sensors' distances).
    start_rad = [math.radians(3.0), math.radians(5.0)]
    pair, probes, samples = ringing_together(start_rad, seed=4)
    lines = lines_of(pair, probes)
    for fit, swing in zip(fit_ringdowns(samples, RATE_HZ, lines), start_rad):
        assert fit.ok, fit.message
        assert swing_from_signal_rad(fit, lines[fit.probe_id].pickup_scale_t) == pytest.approx(swing, rel=0.02)
        assert fit.amplitude_rad == pytest.approx(swing, rel=0.02)  # by its size: the pickup's scale is known
