"""Compile the numba kernels (or load them from numba's on-disk cache) before they are needed.

The ring-down fit (:mod:`mows.estimate.ringdown.model`), the potential's Chebyshev series and
harmonic balance (:mod:`mows.physics.potential`) and the simulator's integrator
(:mod:`mows.sim.kernel`, one for one probe and for a scene of several) are compiled on first
use: about ten seconds on a fresh checkout, about a second from the cache. That must not happen
in the middle of a measurement (a driver that stalls for seconds loses its device link; an
estimator that stalls misses ring-downs), so the nodes and the test session call
:func:`precompile` first.
``python -m mows.precompile`` does it by hand.
"""

import math
import time

import numpy as np

from mows.estimate.ringdown import FitOptions, fit_ringdown
from mows.physics.fluxgate import FluxgatePair
from mows.physics.potential import DEFAULT_NODES, ArcPotential
from mows.physics.probe import PAPER_PROBE


def precompile(simulator: bool = True) -> float:
    """Run one small fit (and, with ``simulator``, a few steps of the simulator with one probe and
    with a scene of several); return the seconds it took."""
    start = time.perf_counter()
    t = np.arange(4000) / 20_000.0
    near = np.sin(0.3 * np.cos(2 * math.pi * 112.0 * t) * np.exp(-1.8 * t))
    pair = np.stack([near, np.zeros_like(near)], axis=1)
    potential = ArcPotential(1.0, 1.0, 0.0, np.zeros(DEFAULT_NODES))
    potential.stiffness_nm_per_rad(0.0)
    potential.effective_stiffness_nm_per_rad(0.1)  # the harmonic balance: the lab's, the calibration's
    fit_ringdown(pair, 20_000.0, 0.0, 112.0, options=FitOptions.lever_aware(FluxgatePair.paper(), PAPER_PROBE, 0.0))
    if simulator:
        # Imported only when asked for: the estimator node (simulator=False) never runs the
        # simulator, and importing it (scipy.signal, the kernels' module) would add seconds to
        # the node's start on top of the fit's modules.
        from mows.sim.scenario import Scenario, load_scenario
        from mows.sim.simulator import SimulatedDevice

        for scenario in (Scenario(), load_scenario("three_probes")):
            SimulatedDevice(scenario).read(10)
    return time.perf_counter() - start


if __name__ == "__main__":
    print(f"numba kernels ready in {precompile():.1f} s")
