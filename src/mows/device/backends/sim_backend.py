"""The simulator as the driver's device (:class:`mows.device.interface.Backend` ``sim``): the
first-principles simulator of a scene's probes (one, or several on one stage) in this process,
paced in real time or unpaced, with commands applied at their exact sample."""

from __future__ import annotations

import dataclasses
import math
import threading
import time

from mows.device.clock import DeviceClock
from mows.device.interface import (
    Backend,
    Command,
    CommandResult,
)
from mows.device.protocol.payloads import DeviceInfo
from mows.device.simulated.scheduled import ScheduledDevice
from mows.physics.coils import CurrentCap
from mows.records.samples import SampleBlock
from mows.sim.readings import SimulatedBlock
from mows.sim.simulator import SimulatedDevice

# The simulator is read in pieces of at least this: each read has a fixed cost (~0.4 ms), and
# reads woken from sleep run on cold caches, so 25 ms pieces cost half of what 10 ms ones do.
SIM_CHUNK_S = 0.025


def simulated_device_info(device: ScheduledDevice) -> DeviceInfo:
    """A DeviceInfo for a simulated device (no link, so no watchdog: infinite timeout)."""
    near = device.device.scenario.sensors.pair.sensors[0]
    return DeviceInfo(
        device.device.sample_rate_hz,
        2,
        device.device.n_coils,
        near.range_t,
        near.resolution_t,
        device.cap.limit_a,
        math.inf,
    )


def stamped(block: SimulatedBlock, clock: DeviceClock) -> SampleBlock:
    """The simulator's samples on the device clock ``clock``."""
    return dataclasses.replace(block.samples, stamp_ns=clock.stamp_ns(block.samples.first_sample_index))


class SimBackend(Backend):
    """The first-principles simulator as a device, in this process.

    Paced (the default), it takes samples as their time comes on the host's monotonic clock
    (:class:`mows.device.clock.DeviceClock`), at least ``chunk_s`` at a time; unpaced (tests,
    benchmarks), each poll takes the next ``chunk_s`` at once. Commands are applied at their
    exact sample by :class:`mows.device.simulated.scheduled.ScheduledDevice`.

    ``probes`` are the scene's probes on its one shared stage, at their home orientations
    (probe id = index), and ``coils`` are the scene's coils, placed among them: the driver's
    cycles drive the probes (:mod:`mows.device.cycle.sequencer`).
    """

    name = "sim"
    can_excite = True

    def __init__(
        self,
        device: SimulatedDevice,
        cap: CurrentCap,
        paced: bool = True,
        clock: DeviceClock | None = None,
        chunk_s: float = SIM_CHUNK_S,
        supply_cap_a: float = math.inf,
        supply_slew_a_per_s: float = math.inf,
    ):
        self.device = ScheduledDevice(device, cap, supply_cap_a, supply_slew_a_per_s)
        self.probes, self.coils = self.device.home, device.setup
        self.supply_limits = self.device.supply_limits
        self._info = simulated_device_info(self.device)
        self.clock = clock or DeviceClock(device.sample_rate_hz)
        self.paced = paced
        self._chunk = max(1, round(chunk_s * device.sample_rate_hz))
        self._results: list[CommandResult] = []
        self._lock = threading.Lock()  # the device is shared with the threads that send commands

    @property
    def info(self) -> DeviceInfo:
        return self._info

    def poll(self, timeout_s: float) -> list:
        if self.paced:
            time.sleep(min(timeout_s, self.clock.seconds_until(self.device.next_index + self._chunk)))
            due = self.clock.due_index()
        else:
            due = self.device.next_index + self._chunk
        with self._lock:
            items: list[CommandResult | SampleBlock] = list(self._results)
            self._results = []
            if due - self.device.next_index >= self._chunk:
                items += [stamped(block, self.clock) for block in self.device.read_until(due)]
        return items

    def send(self, command: Command) -> None:
        with self._lock:
            try:
                self._results.append(CommandResult(command.command_id, True, self.device.schedule(command)))
            except RuntimeError as busy:
                self._results.append(CommandResult(command.command_id, False, reason=str(busy)))

    def coils_off_now(self) -> None:
        with self._lock:
            self.device.switch_off_at(self.device.next_index)

    def supply_to_zero_now(self) -> None:
        with self._lock:
            self.device.supply_to_zero()

    def stats(self) -> dict:
        values = {
            "link": "simulated",
            "device_coils_on": self.device.coils_on,
            "probes": len(self.probes),
            "peak_coil_current_a": self.device.peak_current_a,
        }
        if self.device.supply_limits is not None:
            values.update(
                supply_current_a=self.device.device.field_current_a, supply_target_a=self.device.supply_target_a
            )
        return values

    def close(self) -> None:
        """Coils off, and the supply ramped to zero: the simulated device runs on until it is."""
        self.coils_off_now()
        with self._lock:
            self.device.read_until(self.device.supply_to_zero() + 1)
