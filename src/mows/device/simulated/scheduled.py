"""A simulated device whose commands take effect at chosen sample indices.

Hardware applies a command at a sample of its own clock; so does this wrapper of
:class:`mows.sim.simulator.SimulatedDevice`: commands wait in a queue and ``read_until`` cuts its
reads at their indices. That makes the instant the coils switch off, where a ring-down
starts, exact to the sample. The sim backend and the device emulator both run on it.

The scene's probes (one, or several) sit on one shared stage: a turn to the stage angle θ turns
each to its orientation there (:meth:`mows.sim.scenario.Scenario.stage_orientations_rad`: a
scene's home orientations plus θ, the one probe of a one-probe scene to θ itself). The coils
carry the sum of the tones of a :class:`mows.device.interface.CoilCommand`, one per probe it
drives (one probe's drive is a tone of one); a switch-off (no tones, an emergency stop) switches
every tone off at once.

Every coil command is checked against the current cap (the lower of the driver's and the
scenario's) when it is scheduled, on the tones' summed true peak over the whole excitation
(:func:`mows.physics.multitone.summed_peak_a`), so that nothing above the cap is ever queued,
let alone applied. The static-field supply (:mod:`mows.physics.supply`) likewise: a new supply current is
checked against its cap, rounded to its resolution and reached by a staircase within its slew
limit, each step queued at its sample; cancelling the coils' commands leaves a ramp alone, and
:meth:`ScheduledDevice.supply_to_zero` ramps the supply down from wherever it is.
"""

from __future__ import annotations

import bisect
import collections
import dataclasses
import functools
import math
from collections.abc import Callable, Sequence

import numpy as np

from mows.device.interface import CoilCommand, CoilTone, Command, FieldCurrentCommand, OrientationCommand
from mows.physics.coils import CurrentCap
from mows.physics.multitone import summed_peak_a
from mows.physics.supply import SupplyLimits
from mows.sim.readings import SimulatedBlock
from mows.sim.simulator import NEVER, SimulatedDevice

COIL_LOG_LENGTH = 10000  # coil changes kept (two per excitation)


class OverCap(ValueError):
    """A coil amplitude above the current cap: refused, never clipped."""


class ScheduledDevice:
    """``device`` (its probes on one shared stage) with a command queue; ``cap`` is the driver's
    coil current cap. ``home`` holds the probes at their home orientations; ``peak_current_a``
    is the largest coil current the device carried."""

    def __init__(
        self,
        device: SimulatedDevice,
        cap: CurrentCap,
        supply_cap_a: float = math.inf,
        supply_slew_a_per_s: float = math.inf,
    ):
        stages = {p.stage for p in device.scenario.probes}
        if len(stages) > 1:
            raise ValueError(
                f"scenario {device.scenario.name!r}: its probes are on the stages {sorted(stages)}; "
                "the driver turns one shared stage"
            )
        self.device = device
        self.home = tuple(device.scenario.placed_probes())
        self.peak_current_a = 0.0
        self.cap = CurrentCap(min(cap.limit_a, device.scenario.setup.cap.limit_a))
        supply = device.scenario.supply
        # The lower of the driver's and the supply's own cap and slew limit.
        self.supply_limits = (
            None
            if supply is None
            else SupplyLimits(
                min(supply_cap_a, supply.limits.cap_a),
                min(supply_slew_a_per_s, supply.limits.slew_a_per_s),
                supply.limits.resolution_a,
                supply.limits.polarity,
            )
        )
        self.supply_target_a = 0.0 if supply is None else device.field_current_a
        self._supply_free_index = 0  # the sample after the last queued supply step
        # (sample index, arrival order, kind, action): kind is "turn", "on", "off" or "supply"
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
        """Coils on, or a switch-on or a turn of the stage waiting. A waiting switch-off is not:
        with the coils off it changes nothing (the host sends one whenever the link comes up,
        and a turn that reaches the device in the same read must not be refused for it); with
        them on, ``coils_on`` already says busy. Nor is a supply ramp."""
        return self.coils_on or any(entry[2] in ("on", "turn") for entry in self._queue)

    def check_coils(self, tones: Sequence[CoilTone], samples: int = 0) -> tuple[CoilTone, ...]:
        """``tones`` as a tuple if the device can drive them for ``samples`` samples (0: until the
        next coil command); OverCap when their summed peak over those samples is above the cap,
        ValueError for anything else malformed."""
        tones = tuple(tones)
        ids = [t.probe_id for t in tones] if all(isinstance(t, CoilTone) for t in tones) else None
        if ids is None or len(set(ids)) != len(ids) or not set(ids) <= set(range(len(self.home))):
            raise ValueError(f"tones {tones!r} must be Tones of distinct probes 0 to {len(self.home) - 1}")
        if not (isinstance(samples, (int, np.integer)) and samples >= 0):
            raise ValueError(f"samples = {samples!r} must be an integer ≥ 0")
        n_coils, nyquist_hz = self.device.n_coils, self.device.sample_rate_hz / 2.0
        for t in tones:
            amplitudes = np.asarray(t.amplitudes_a, dtype=float)
            if not np.all(np.isfinite(amplitudes)):
                raise ValueError(f"coil amplitudes must be finite, got {t.amplitudes_a!r}")
            if amplitudes.shape != (n_coils,):
                raise ValueError(f"{amplitudes.size} coil amplitudes given; the device has {n_coils} coils")
            if amplitudes.any() and not (math.isfinite(t.frequency_hz) and 0.0 < t.frequency_hz < nyquist_hz):
                raise ValueError(f"frequency_hz = {t.frequency_hz!r} must be in (0, {nyquist_hz:g}) Hz")
        active = [t for t in tones if any(t.amplitudes_a)]
        if active:
            duration_s = samples / self.device.sample_rate_hz if samples else math.inf
            rows = [t.amplitudes_a for t in active]
            peak = float(summed_peak_a(rows, [t.frequency_hz for t in active], duration_s).max())
            if peak > self.cap.limit_a:
                raise OverCap(
                    f"the tones of probes {ids} peak at {peak:.6g} A, above the {self.cap.limit_a:g} A cap "
                    "(a drive that exceeds the cap is refused, never clipped)"
                )
        return tuple(dataclasses.replace(t, amplitudes_a=tuple(float(a) for a in t.amplitudes_a)) for t in tones)

    def schedule_coils(self, at_index: int, tones: Sequence[CoilTone], samples: int = 0) -> int:
        """Drive the coils with the sum of ``tones`` for ``samples`` samples (0: until the next
        coil command) from sample ``at_index`` (no tones, or all of zero current: off); returns
        the sample it applies at. OverCap above the cap, ValueError for a malformed drive;
        RuntimeError while a turn of the stage waits."""
        checked = self.check_coils(tones, samples)
        on = any(any(t.amplitudes_a) for t in checked)
        if on and any(entry[2] == "turn" for entry in self._queue):
            raise RuntimeError("coils cannot go on while a turn of the stage is waiting")
        return self._enqueue(at_index, "on" if on else "off", functools.partial(self._drive, checked, int(samples)))

    def schedule(self, command: Command) -> int:
        """A driver's command at its sample: the index where it applies. RuntimeError while
        the device is busy with another, ValueError for one it refuses."""
        if isinstance(command, CoilCommand):
            return self.schedule_coils(command.at_sample_index, command.tones, command.samples)
        if isinstance(command, FieldCurrentCommand):
            return self.schedule_field_current(command.at_sample_index, command.current_a)
        assert isinstance(command, OrientationCommand)  # the commands a driver sends
        return self.schedule_orientation(command.at_sample_index, command.theta0_rad)

    def schedule_orientation(self, at_index: int, theta0_rad: float) -> int:
        """Turn the stage to ``theta0_rad`` at sample ``at_index``; returns the sample it applies at.
        ValueError for a non-finite angle; RuntimeError while the coils are on or a switch-on or a turn waits."""
        if not math.isfinite(theta0_rad):
            raise ValueError(f"theta0_rad = {theta0_rad!r} must be finite")
        if self.busy:
            raise RuntimeError("the probe cannot turn while the coils are on or a command waits")
        return self._enqueue(at_index, "turn", functools.partial(self._turn, float(theta0_rad)))

    def _turn(self, theta0_rad: float) -> None:
        self.device.set_orientations(self.device.scenario.stage_orientations_rad(theta0_rad))

    def cancel(self) -> None:
        """Forget every waiting command of the coils and the stage (a supply ramp goes on: it
        is never left half-way)."""
        self._queue[:] = [entry for entry in self._queue if entry[2] == "supply"]

    def schedule_field_current(self, at_index: int, current_a: float) -> int:
        """Ramp the supply to ``current_a`` from sample ``at_index`` (after any ramp already
        queued); returns the sample at which it reaches the target. ValueError without a supply,
        above its cap or for a non-finite current."""
        if self.supply_limits is None:
            raise ValueError("the device has no field supply")
        target = self.supply_limits.check(current_a)
        start = max(int(at_index), self.next_index, self._supply_free_index)
        return self._ramp(start, self.supply_target_a, target)

    def supply_to_zero(self) -> int:
        """Forget queued supply steps and ramp down from the present current from the next
        sample; returns the sample at which the supply is at zero (never raises)."""
        if self.supply_limits is None:
            return self.next_index
        self._queue[:] = [entry for entry in self._queue if entry[2] != "supply"]
        return self._ramp(self.next_index, self.device.field_current_a, 0.0)

    def _ramp(self, start: int, from_a: float, to_a: float) -> int:
        assert self.supply_limits is not None  # callers have checked that there is a supply
        applied = start
        for offset_s, current in self.supply_limits.ramp(from_a, to_a):
            applied = self._enqueue(
                start + round(offset_s * self.device.sample_rate_hz),
                "supply",
                functools.partial(self.device.set_field_current, current),
            )
        self.supply_target_a = to_a
        self._supply_free_index = applied + 1
        return applied

    def switch_off_at(self, at_index: int) -> int:
        """Cancel every waiting command and switch the coils off at ``at_index`` (the next
        sample if that has passed); returns the sample it applies at."""
        self.cancel()
        return self._enqueue(at_index, "off", functools.partial(self._drive, (), 0))

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

    def idle_until(self, end_index: int) -> int:
        """Let the probe move on to ``end_index`` (exclusive) without reading the sensors, for
        stretches nobody records (a gap with the coils off): the motion is integrated sample by
        sample as in :meth:`read_until`; only the pick-up and the noise are not computed. Stops
        at the first waiting command, which :meth:`read_until` then applies; returns the sample
        reached. RuntimeError while the coils are on (their samples are always read)."""
        if self.coils_on:
            raise RuntimeError("the coils are on: their samples are read, not skipped")
        stop = min(int(end_index), self._queue[0][0]) if self._queue else int(end_index)
        if stop > self.next_index:
            self.device.integrate(stop - self.next_index)
        return self.next_index

    def _log_coils(self, block: SimulatedBlock) -> None:
        changes = np.flatnonzero(np.diff(block.coils_on.astype(np.int8), prepend=np.int8(self._logged_on)))
        for i in changes:
            self._logged_on = bool(block.coils_on[i])
            self.coil_log.append((block.samples.first_sample_index + int(i), self._logged_on))
        if block.currents_a.size:
            self.peak_current_a = max(self.peak_current_a, float(np.max(np.abs(block.currents_a))))

    def _drive(self, tones: tuple[CoilTone, ...], samples: int) -> None:
        active = [t for t in tones if any(t.amplitudes_a)]
        if active:
            off_index = self.device.sample_index + samples if samples else NEVER
            self.device.drive([t.amplitudes_a for t in active], [t.frequency_hz for t in active], off_index)
        else:
            self.device.coils_off()
        self.coils_on = bool(active)
