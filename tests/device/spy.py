"""A simulated device that records every coil drive it is given (what reached the device)."""

import numpy as np

from mows.sim.simulator import SimulatedDevice


class SpyDevice(SimulatedDevice):
    def __init__(self, scenario):
        super().__init__(scenario)
        self.drives = []

    def drive(self, amplitudes_a, frequencies_hz, *off_index):
        self.drives.extend(np.array(amplitudes_a, float))
        super().drive(amplitudes_a, frequencies_hz, *off_index)
