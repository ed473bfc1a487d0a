"""One simulated measurement cycle: turn, excite, switch off, record the ring-down (:func:`simulate_cycle`),
and its record with the truth to compare a fit with (:class:`CycleRecord`)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.physics.coils import excitation_samples
from mows.physics.potential import ArcPotential
from mows.sim.simulator import SimulatedBlock, SimulatedDevice


@dataclasses.dataclass(frozen=True, eq=False)
class CycleRecord:
    """One excitation and its ring-down. ``block`` holds the samples (and the truth θ(t));
    the ring-down starts at ``coil_off_index``; ``potential`` is U(θ) at the switch-off."""

    theta0_rad: float
    currents_a: np.ndarray
    frequency_hz: float
    block: SimulatedBlock
    coil_off_index: int
    potential: ArcPotential

    @property
    def sample_rate_hz(self) -> float:
        return self.block.samples.sample_rate_hz

    @property
    def samples_t(self) -> np.ndarray:
        return self.block.samples.samples_t

    @property
    def saturated(self) -> np.ndarray:
        return self.block.samples.saturated

    @property
    def theta_rad(self) -> np.ndarray:
        """The deflection of the probe (the first of a scene) at the samples (n,)."""
        return self.block.theta_rad[:, 0]

    def expected_frequency_hz(self, amplitude_rad=0.0):
        """Truth f(A) from the full potential (harmonic balance, Eq. S1)."""
        return self.potential.frequency_hz(amplitude_rad)

    def ringdown_amplitude_rad(self) -> float:
        """The first swing after switch-off: max |θ − θs| over the first period of the ring-down."""
        period = int(math.ceil(self.sample_rate_hz / self.frequency_hz))
        theta = self.theta_rad[self.coil_off_index : self.coil_off_index + period]
        return float(np.max(np.abs(theta - self.potential.rest_angle_rad())))

    def ringdown_frequency_hz(self, duration_s: float, points: int = 32) -> float:
        """Truth for a fit of the first ``duration_s`` of the ring-down: the time average of
        f(A(t)) with A(t) = A0·e^(−δt) from the first swing A0 (the frequency drifts as the
        amplitude decays, docs/physics.md §6.3, §6.5)."""
        t = (np.arange(points) + 0.5) / points * duration_s
        amplitudes = self.ringdown_amplitude_rad() * np.exp(-float(self.potential.damping_per_s) * t)
        return float(np.mean([self.potential.frequency_hz(a) for a in amplitudes]))


def simulate_cycle(
    device: SimulatedDevice,
    theta0_rad: float,
    amplitude_a: float,
    frequency_hz=None,
    excite_s: float = 0.5,
    ringdown_s: float = 0.5,
) -> CycleRecord:
    """Turn the device's stage to θ0 (:meth:`mows.sim.scenario.Scenario.stage_orientations_rad`: the
    probe of a one-probe scene to θ0), drive the coils with the setup's current scheme for ``excite_s`` (base
    amplitude ``amplitude_a``; ``frequency_hz`` None: the expected small-amplitude frequency,
    as after the paper's tuning), switch them off at the drive current's peak nearest
    ``excite_s`` (:func:`mows.physics.coils.excitation_samples`) and record ``ringdown_s`` of
    ring-down."""
    device.set_orientations(device.scenario.stage_orientations_rad(theta0_rad))
    frequency = device.expected_frequency_hz() if frequency_hz is None else float(frequency_hz)
    currents = device.scenario.setup.currents_a(theta0_rad, amplitude_a)
    device.set_coils(currents, frequency)
    excitation = device.read(excitation_samples(excite_s, frequency, device.sample_rate_hz))
    device.coils_off()
    potential = device.potential()
    ringdown = device.read(int(round(ringdown_s * device.sample_rate_hz)))
    return CycleRecord(
        float(theta0_rad),
        currents,
        frequency,
        SimulatedBlock.concatenate([excitation, ringdown]),
        len(excitation),
        potential,
    )
