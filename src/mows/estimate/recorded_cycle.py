"""The ring-down of one recorded cycle, fitted as the estimator node fits it.

A recorded cycle is any object with the cycle's samples (``samples_t``, ``saturated``), its
``sample_rate_hz``, commanded ``theta0_rad``, excitation ``frequency_hz`` and the sample index
of the coil switch-off (``coil_off_index``), such as :class:`mows.device.stream.simulated_cycle.CycleRecord`; the
scene only lends its probe and fluxgate pair (``scene.probe``, ``scene.sensors.pair``). The
simulator, the calibration command and ``mows sim`` fit their cycles here, so that all of them
fit exactly as the node does.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, RingdownFit, fit_ringdown
from mows.physics.fluxgate import FluxgatePair
from mows.physics.probe import Probe


class RecordedCycle(Protocol):
    """What :func:`fit_cycle` reads of a recorded cycle (module docstring)."""

    @property
    def samples_t(self) -> np.ndarray: ...
    @property
    def saturated(self) -> np.ndarray: ...
    @property
    def sample_rate_hz(self) -> float: ...
    @property
    def theta0_rad(self) -> float: ...
    @property
    def frequency_hz(self) -> float: ...
    @property
    def coil_off_index(self) -> int: ...


class _Sensors(Protocol):
    @property
    def pair(self) -> FluxgatePair: ...


class Scene(Protocol):
    """What :func:`fit_cycle` reads of a scene: its probe and fluxgate pair."""

    @property
    def probe(self) -> Probe: ...
    @property
    def sensors(self) -> _Sensors: ...


def fit_cycle(
    cycle: RecordedCycle, scene: Scene, paper_model: bool = False, coil_off_skip_s: float = COIL_OFF_SKIP_S
) -> RingdownFit:
    """Fit the ring-down of a recorded cycle: the lever-aware pickup of ``scene``'s probe seen by
    its fluxgates at the commanded θ0 (``paper_model``: Eq. S11 instead), the expected frequency
    the one the cycle excited at, the probe's damping as the start."""
    options = FitOptions() if paper_model else FitOptions.lever_aware(scene.sensors.pair, scene.probe, cycle.theta0_rad)
    start = cycle.coil_off_index
    return fit_ringdown(
        cycle.samples_t[start:],
        cycle.sample_rate_hz,
        cycle.theta0_rad,
        cycle.frequency_hz,
        cycle.saturated[start:],
        options,
        scene.probe.damping_per_s,
        coil_off_skip_s,
    )
