"""A simulated device whose commands take effect at chosen sample indices.

Hardware applies a command at a sample of its own clock; so does this wrapper of
:class:`mows.sim.simulator.SimulatedDevice`: commands wait in a queue and ``read_until`` cuts its
reads at their indices. That makes the instant the coils switch off, where a ring-down
starts, exact to the sample. The sim backend and the device emulator both run on it.

Every coil command is checked against the current cap (the lower of the driver's and the
scenario's) when it is scheduled, so that nothing above the cap is ever queued, let alone
applied.
"""
from __future__ import annotations

import bisect
import collections
import functools
import math
from collections.abc import Callable

import numpy as np

from mows.physics.coils import CurrentCap
from mows.sim.simulator import SimulatedBlock, SimulatedDevice

COIL_LOG_LENGTH = 10000  # coil changes kept (two per excitation)


class OverCap(ValueError):
    """A coil amplitude above the current cap: refused, never clipped."""


class ScheduledDevice:
    """``device`` with a command queue; ``cap`` is the driver's coil current cap."""

    def __init__(self, device: SimulatedDevice, cap: CurrentCap):
        self.device = device
        self.cap = CurrentCap(min(cap.limit_a, device.scenario.setup.cap.limit_a))
        # (sample index, arrival order, kind, action): kind is "turn", "on" or "off"
        self._queue: list[tuple[int, int, str, Callable[[], None]]] = []
        self._arrivals = 0
        self.coils_on = False
        # The device's own record of its coils: (first sample, on) at every change, taken
        # from the samples' coil flags, not from the commands.
        self.coil_log: collections.deque = collections.deque(maxlen=COIL_LOG_LENGTH)
        self._logged_on = False

    @property
    def next_index(self) -> int:
        """The next sample the device will take; commands for earlier samples apply here."""
        return self.device.sample_index

    @property
    def busy(self) -> bool:
        """Coils on, or a command waiting."""
        return bool(self._queue) or self.coils_on

    def check_coils(self, amplitudes_a, frequency_hz: float) -> tuple:
        """The amplitudes as a tuple if the device can take them; OverCap above the cap,
        ValueError for anything else malformed."""
        amplitudes = np.asarray(amplitudes_a, dtype=float).reshape(-1)
        if not np.all(np.isfinite(amplitudes)):
            raise ValueError(f"coil amplitudes must be finite, got {amplitudes_a!r}")
        try:
            self.cap.check(amplitudes)
        except ValueError as above:
            raise OverCap(str(above)) from None
        if amplitudes.shape != (self.device.n_coils,):
            raise ValueError(f"{amplitudes.size} coil amplitudes given; the device has {self.device.n_coils} coils")
        nyquist_hz = self.device.sample_rate_hz / 2.0
        if amplitudes.any() and not (math.isfinite(frequency_hz) and 0.0 < frequency_hz < nyquist_hz):
            raise ValueError(f"frequency_hz = {frequency_hz!r} must be in (0, {nyquist_hz:g}) Hz")
        return tuple(float(a) for a in amplitudes)

    def schedule_coils(self, at_index: int, amplitudes_a, frequency_hz: float) -> int:
        """Drive the coils from sample ``at_index`` (all zero: off); returns the sample it
        applies at. ValueError above the cap or for a malformed drive; RuntimeError while a
        turn of the probe waits."""
        amplitudes = self.check_coils(amplitudes_a, frequency_hz)
        kind = "on" if any(amplitudes) else "off"
        if kind == "on" and any(entry[2] == "turn" for entry in self._queue):
            raise RuntimeError("coils cannot go on while a turn of the probe is waiting")
        return self._enqueue(at_index, kind, functools.partial(self._drive, amplitudes, float(frequency_hz)))

    def schedule_orientation(self, at_index: int, theta0_rad: float) -> int:
        """Turn the probe at sample ``at_index``; returns the sample it applies at.
        ValueError for a non-finite angle; RuntimeError while the coils are on or commanded."""
        if not math.isfinite(theta0_rad):
            raise ValueError(f"theta0_rad = {theta0_rad!r} must be finite")
        if self.busy:
            raise RuntimeError("the probe cannot turn while the coils are on or a command waits")
        return self._enqueue(at_index, "turn", functools.partial(self.device.set_orientation, float(theta0_rad)))

    def cancel(self) -> None:
        """Forget every waiting command."""
        self._queue.clear()

    def switch_off_at(self, at_index: int) -> int:
        """Cancel every waiting command and switch the coils off at ``at_index`` (the next
        sample if that has passed); returns the sample it applies at."""
        self.cancel()
        return self._enqueue(at_index, "off", functools.partial(self._drive, (0.0,) * self.device.n_coils, 0.0))

    def _enqueue(self, at_index: int, kind: str, action: Callable[[], None]) -> int:
        applied = max(int(at_index), self.next_index)
        bisect.insort(self._queue, (applied, self._arrivals, kind, action), key=lambda entry: entry[:2])
        self._arrivals += 1
        return applied

    def read_until(self, end_index: int) -> list[SimulatedBlock]:
        """Take samples up to ``end_index`` (exclusive), applying each command at its sample."""
        blocks = []
        while self.next_index < end_index:
            while self._queue and self._queue[0][0] <= self.next_index:
                self._queue.pop(0)[3]()
            stop = min(end_index, self._queue[0][0]) if self._queue else end_index
            block = self.device.read(stop - self.next_index)
            self._log_coils(block)
            blocks.append(block)
        return blocks

    def _log_coils(self, block: SimulatedBlock) -> None:
        changes = np.flatnonzero(np.diff(block.coils_on.astype(np.int8), prepend=np.int8(self._logged_on)))
        for i in changes:
            self._logged_on = bool(block.coils_on[i])
            self.coil_log.append((block.samples.first_sample_index + int(i), self._logged_on))

    def _drive(self, amplitudes_a: tuple, frequency_hz: float) -> None:
        if any(amplitudes_a):
            self.device.set_coils(np.array(amplitudes_a), frequency_hz)
        else:
            self.device.coils_off()
        self.coils_on = any(amplitudes_a)
