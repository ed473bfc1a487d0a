"""A simulated device that records every coil drive it is given (what reached the device)."""

import numpy as np

from mows.sim.simulator import SimulatedDevice


class SpyDevice(SimulatedDevice):
    def __init__(self, scenario):
        super().__init__(scenario)
        self.drives = []

    def set_coils(self, amplitudes_a, frequency_hz):
        self.drives.append(np.array(amplitudes_a, float))
        super().set_coils(amplitudes_a, frequency_hz)
