"""What the simulated device returns (:class:`mows.sim.simulator.SimulatedDevice`): the two
fluxgates' reading of its swinging magnets (:func:`swinging_pickup_t`), a read's samples with the
simulation's truth at them (:class:`SimulatedBlock`), and each probe's state and potential
(:class:`DeviceTruth`), which hardware would not know.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from mows.physics.coupling import PlacedProbe
from mows.physics.fluxgate import FluxgatePair
from mows.physics.potential import ArcPotential
from mows.records.samples import SampleBlock


def swinging_pickup_t(pair: FluxgatePair, placed: Sequence[PlacedProbe], theta_rad: np.ndarray) -> np.ndarray:
    """What both fluxgates of ``pair`` read, (n, 2) T, of the magnets ``placed`` swinging through
    the deflections ``theta_rad`` (n, N): each magnet's exact dipole field (Eq. S8) on its
    lever, summed."""
    field = np.zeros((theta_rad.shape[0], 2))
    for k, p in enumerate(placed):
        positions = p.pose.magnet_position_at(theta_rad[:, k], p.probe.lever_m)
        field += pair.pickup_t(positions, p.probe.moment_am2 * p.pose.moment_direction_at(theta_rad[:, k]))
    return field


@dataclasses.dataclass(frozen=True, eq=False)
class SimulatedBlock:
    """What the device read (``samples``: a :class:`~mows.records.samples.SampleBlock` of both
    fluxgates, column 0 the near sensor, stamped on a device clock that starts at 0) and the
    simulation's truth at those samples, which hardware would not know: ``coils_on`` (n,), each
    probe's ``theta_rad`` and ``theta_dot_rad_per_s`` (n, N), the coil currents ``currents_a``
    (n, n_coils)."""

    samples: SampleBlock
    coils_on: np.ndarray
    theta_rad: np.ndarray
    theta_dot_rad_per_s: np.ndarray
    currents_a: np.ndarray

    def __len__(self) -> int:
        return len(self.samples)

    @staticmethod
    def concatenate(blocks) -> SimulatedBlock:
        """One block of consecutive ``blocks``."""
        blocks = list(blocks)
        truth = {
            f.name: np.concatenate([getattr(b, f.name) for b in blocks])
            for f in dataclasses.fields(SimulatedBlock)
            if f.name != "samples"
        }
        return SimulatedBlock(SampleBlock.concatenate(b.samples for b in blocks), **truth)


@dataclasses.dataclass(frozen=True, eq=False)
class DeviceTruth:
    """What the simulation knows and the hardware would not: each probe's state (N,) and potential."""

    time_s: float
    theta0_rad: np.ndarray
    theta_rad: np.ndarray
    theta_dot_rad_per_s: np.ndarray
    rest_angle_rad: np.ndarray
    temperature_k: float
    spring_nm_per_rad: np.ndarray
    field_t: np.ndarray  # (N, 3) static field at each magnet's rest position, global frame, neighbours left out
    gradient_t_per_m: np.ndarray  # (N, 3, 3) G[i, j] = ∂B_i/∂x_j there
    potentials: tuple[ArcPotential, ...]  # U(θ) of each probe at this pose and temperature
