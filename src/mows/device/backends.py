"""The driver's backends behind :class:`mows.device.interface.Backend`: the simulator paced in
real time (``sim``), a device on a serial port (``serial``), a recorded bag (``bag``)."""
from __future__ import annotations

import collections
import dataclasses
import itertools
import math
import os
import threading
import time

import numpy as np

from mows.device import bags
from mows.device.clock import DeviceClock
from mows.device.interface import (
    Backend,
    CoilCommand,
    Command,
    CommandResult,
    DeviceFault,
    FieldCurrentCommand,
    LinkEvent,
    NotExciting,
    check_coil_command,
)
from mows.device.payloads import Ack, Coils, DeviceInfo, FieldCurrent, Orientation, Samples, Status
from mows.device.phases import Phase, PhaseEvent
from mows.device.scheduled import ScheduledDevice
from mows.device.serial_link import SerialLink
from mows.physics.coils import CurrentCap
from mows.records import stamps
from mows.records.samples import SampleBlock
from mows.sim.simulator import SimulatedBlock, SimulatedDevice

# The simulator is read in pieces of at least this: each read has a fixed cost (~0.4 ms), and
# reads woken from sleep run on cold caches, so 25 ms pieces cost half of what 10 ms ones do.
SIM_CHUNK_S = 0.025
COMMAND_LEAD_S = 0.05   # serial commands are scheduled this far ahead of the newest sample
RAW_TYPE = "mows_msgs/msg/MagnetometerBlock"
EXCITATION_TYPE = "mows_msgs/msg/ExcitationState"


def simulated_device_info(device: ScheduledDevice) -> DeviceInfo:
    """A DeviceInfo for a simulated device (no link, so no watchdog: infinite timeout)."""
    near = device.device.scenario.sensors.pair.sensors[0]
    return DeviceInfo(device.device.sample_rate_hz, 2, device.device.n_coils, near.range_t, near.resolution_t,
                      device.cap.limit_a, math.inf)


def stamped(block: SimulatedBlock, clock: DeviceClock) -> SampleBlock:
    """The simulator's samples on the device clock ``clock``."""
    return dataclasses.replace(block.samples, stamp_ns=clock.stamp_ns(block.samples.first_sample_index))


class SimBackend(Backend):
    """The first-principles simulator as a device, in this process.

    Paced (the default), it takes samples as their time comes on the host's monotonic clock
    (:class:`mows.device.clock.DeviceClock`), at least ``chunk_s`` at a time; unpaced (tests,
    benchmarks), each poll takes the next ``chunk_s`` at once. Commands are applied at their
    exact sample by :class:`mows.device.scheduled.ScheduledDevice`.
    """

    name = "sim"
    can_excite = True

    def __init__(self, device: SimulatedDevice, cap: CurrentCap, paced: bool = True,
                 clock: DeviceClock | None = None, chunk_s: float = SIM_CHUNK_S, supply_cap_a: float = math.inf,
                 supply_slew_a_per_s: float = math.inf):
        self.device = ScheduledDevice(device, cap, supply_cap_a, supply_slew_a_per_s)
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
                if isinstance(command, CoilCommand):
                    applied = self.device.schedule_coils(command.at_sample_index, command.amplitudes_a,
                                                         command.frequency_hz)
                elif isinstance(command, FieldCurrentCommand):
                    applied = self.device.schedule_field_current(command.at_sample_index, command.current_a)
                else:
                    applied = self.device.schedule_orientation(command.at_sample_index, command.theta0_rad)
                self._results.append(CommandResult(command.command_id, True, applied))
            except RuntimeError as busy:
                self._results.append(CommandResult(command.command_id, False, reason=str(busy)))

    def coils_off_now(self) -> None:
        with self._lock:
            self.device.switch_off_at(self.device.next_index)

    def supply_to_zero_now(self) -> None:
        with self._lock:
            self.device.supply_to_zero()

    def stats(self) -> dict:
        values = {"link": "simulated", "device_coils_on": self.device.coils_on}
        if self.device.supply_limits is not None:
            values.update(supply_current_a=self.device.device.field_current_a,
                          supply_target_a=self.device.supply_target_a)
        return values

    def close(self) -> None:
        """Coils off, and the supply ramped to zero: the simulated device runs on until it is."""
        self.coils_off_now()
        with self._lock:
            self.device.read_until(self.device.supply_to_zero() + 1)


class SerialBackend(Backend):
    """A device on a serial port (:class:`mows.device.serial_link.SerialLink`).

    Coil commands above the cap are refused here and never written; the device checks them
    again against its own cap. ``command_lead_s`` covers the link's latency, so that a
    command reaches the device before the sample it is scheduled for.
    """

    name = "serial"
    can_excite = True

    def __init__(self, link: SerialLink, cap: CurrentCap, command_lead_s: float = COMMAND_LEAD_S):
        self.link = link
        self.cap = cap
        self.command_lead_s = command_lead_s
        self.device_status: Status | None = None
        self.samples_before_info = 0  # Samples frames that came before the device described itself
        # Up once the LinkEvent saying so has been passed on: samples queued before it (stale
        # ones from before Hello was answered) must not reach the driver ahead of it.
        self._up = False
        self._pending: dict[int, int] = {}  # frame sequence → command id, until acked
        self._lock = threading.Lock()       # sending and registering a command is one step

    @property
    def info(self) -> DeviceInfo | None:
        return self.link.info

    @property
    def command_lead_samples(self) -> int:
        return round(self.command_lead_s * self.info.sample_rate_hz) if self.info else 0

    def poll(self, timeout_s: float) -> list:
        items: list[LinkEvent | SampleBlock | CommandResult | DeviceFault] = []
        for item in self.link.poll(timeout_s):
            if isinstance(item, LinkEvent):
                with self._lock:
                    self._pending.clear()  # the sequencer fails its cycle on the link event
                self._up = item.up
                items.append(item)
            elif isinstance(item.body, Samples):
                items += self._chunk(item.body, item.timestamp_ns)
            elif isinstance(item.body, Ack):
                items += self._result(item.body)
            elif isinstance(item.body, Status):
                items += self._status(item.body)
        return items

    def _status(self, status: Status) -> list[DeviceFault]:
        """A rise of the device's watchdog trips is a fault (the device sends that Status
        before the samples in which its coils go off)."""
        before, self.device_status = self.device_status, status
        if before is None or status.watchdog_trips <= before.watchdog_trips:
            return []
        return [DeviceFault(f"the device's watchdog switched the coils off (trip {status.watchdog_trips})")]

    def _chunk(self, body: Samples, timestamp_ns: int) -> list[SampleBlock]:
        if not self._up:
            self.samples_before_info += 1
            return []
        info = self.info
        assert info is not None  # the link came up when the device described itself (SerialLink)
        return [SampleBlock(body.first_sample_index, timestamp_ns, info.sample_rate_hz,
                            body.counts * info.resolution_t, body.saturated)]

    def _result(self, ack: Ack) -> list[CommandResult]:
        with self._lock:
            command_id = self._pending.pop(ack.command_sequence, None)
        if command_id is None:
            return []  # an answer to a command of an earlier connection
        return [CommandResult(command_id, ack.accepted, ack.applied_sample_index,
                              "" if ack.accepted else f"device: {ack.reason}")]

    def send(self, command: Command) -> None:
        if self.info is None:
            raise NotExciting("the device has not described itself yet")
        body: Coils | Orientation | FieldCurrent
        if isinstance(command, CoilCommand):
            check_coil_command(command, self.info, self.cap.limit_a)
            body = Coils(0, command.at_sample_index, command.frequency_hz, tuple(command.amplitudes_a))
        elif isinstance(command, FieldCurrentCommand):
            body = FieldCurrent(0, command.at_sample_index, float(command.current_a))
        else:
            body = Orientation(command.at_sample_index, command.theta0_rad)
        with self._lock:
            self._pending[self.link.send(body)] = command.command_id

    def coils_off_now(self) -> None:
        if self.info is None:
            return
        try:
            self.link.send(Coils(Coils.IMMEDIATE, 0, 0.0, (0.0,) * self.info.n_coils))
        except NotExciting:
            pass  # the link is down: the device's watchdog switches the coils off

    def supply_to_zero_now(self) -> None:
        if self.info is None:
            return
        try:
            self.link.send(FieldCurrent(FieldCurrent.TO_ZERO_NOW, 0, 0.0))
        except NotExciting:
            pass  # the link is down: the device's watchdog ramps the supply to zero

    def stats(self) -> dict:
        values = {**self.link.stats(), "samples_frames_before_info": self.samples_before_info}
        if self.device_status is not None:
            s = self.device_status
            values.update(device_coils_on=s.coils_on, device_watchdog_trips=s.watchdog_trips,
                          device_dropped_frames=s.dropped_frames, device_rejected_frames=s.rejected_frames)
        return values

    def close(self) -> None:
        self.coils_off_now()
        self.supply_to_zero_now()
        self.link.close()


class BagBackend(Backend):
    """A recorded rosbag2 bag (the driver's own recordings: MagnetometerBlock and
    ExcitationState messages, on whatever topics) replayed through the driver's path.

    Messages come out in bag order, each when its device stamp is due at ``rate`` × real
    time from the first (counted from the first poll); their stamps stay the recorded device
    stamps. A message that does
    not make sense (channels of unequal length, an unknown phase) is skipped and counted.
    When the bag ends the link goes down ("end of the recording") and stays down.
    """

    name = "bag"
    can_excite = False

    def __init__(self, path: str | os.PathLike, rate: float = 1.0, monotonic=time.monotonic):
        if not (math.isfinite(rate) and rate > 0.0):
            raise ValueError(f"bag_rate = {rate!r} must be a positive multiple of real time")
        self.path, self.rate = str(path), float(rate)
        self.replayed = 0
        self.skipped: dict[str, int] = {}  # messages that made no sense, by why
        self._monotonic = monotonic
        self._messages = (m for m in bags.read_bag(path) if m.msgtype in (RAW_TYPE, EXCITATION_TYPE))
        self._ahead: collections.deque[bags.BagMessage] = collections.deque()
        first_raw = self._first_raw()
        block = first_raw.message
        if not (math.isfinite(block.sample_rate_hz) and block.sample_rate_hz > 0 and block.channels):
            raise ValueError(f"the bag {self.path} starts with a block of sample rate {block.sample_rate_hz!r} Hz "
                             f"and {len(block.channels)} channels: nothing to replay")
        self._info = DeviceInfo(block.sample_rate_hz, len(block.channels), 0, block.range_t, block.resolution_t,
                                0.0, math.inf)
        # maps device stamps to sample indices
        self._anchor = (block.first_sample_index, stamps.nanoseconds(block.header.stamp))
        self._start: tuple[int, float] | None = None  # (first device stamp, host time): set by the first poll
        self._finished = False

    @property
    def info(self) -> DeviceInfo:
        return self._info

    def _first_raw(self) -> bags.BagMessage:
        for message in self._messages:
            self._ahead.append(message)
            if message.msgtype == RAW_TYPE:
                return message
        raise ValueError(f"the bag {self.path} holds no {RAW_TYPE} messages to replay")

    def poll(self, timeout_s: float) -> list:
        deadline = self._monotonic() + timeout_s
        if self._start is None:  # the replay's clock starts with the first poll
            self._start = (stamps.nanoseconds(self._ahead[0].message.header.stamp), self._monotonic())
        items: list[SampleBlock | PhaseEvent | LinkEvent] = []
        while (message := self._peek()) is not None:
            elapsed_ns = stamps.nanoseconds(message.message.header.stamp) - self._start[0]
            due = self._start[1] + elapsed_ns / 1e9 / self.rate
            now = self._monotonic()
            if due > now:
                if items or now >= deadline:
                    return items
                time.sleep(min(due, deadline) - now)
                continue
            self._ahead.popleft()
            items += self._replay(message)
        if not self._finished:
            self._finished = True
            return items + [LinkEvent(False, "end of the recording")]
        time.sleep(timeout_s)
        return items

    def _peek(self) -> bags.BagMessage | None:
        if not self._ahead:
            self._ahead.extend(itertools.islice(self._messages, 1))
        return self._ahead[0] if self._ahead else None

    def _replay(self, message: bags.BagMessage) -> list:
        try:
            item = self._chunk(message.message) if message.msgtype == RAW_TYPE else self._event(message.message)
        except ValueError as nonsense:
            reason = str(nonsense)
            self.skipped[reason] = self.skipped.get(reason, 0) + 1
            return []
        self.replayed += 1
        return [item]

    def _chunk(self, block) -> SampleBlock:
        lengths = {len(c.field_t) for c in block.channels} | {len(c.saturated) for c in block.channels}
        if len(lengths) != 1 or len(block.channels) != self.info.n_channels or block.sample_rate_hz != \
                self.info.sample_rate_hz:
            raise ValueError("a block whose channels or rate do not match the recording's")
        stamp = stamps.nanoseconds(block.header.stamp)
        self._anchor = (block.first_sample_index, stamp)
        return SampleBlock(block.first_sample_index, stamp, self.info.sample_rate_hz,
                           np.stack([c.field_t for c in block.channels], axis=1),
                           np.stack([c.saturated for c in block.channels], axis=1).astype(bool))

    def _event(self, state) -> PhaseEvent:
        if state.phase not in set(Phase):
            raise ValueError(f"an excitation state with the unknown phase {state.phase}")
        stamp = stamps.nanoseconds(state.header.stamp)
        index = self._anchor[0] + round((stamp - self._anchor[1]) * self.info.sample_rate_hz / 1e9)
        return PhaseEvent(Phase(state.phase), index, stamp, state.cycle_id, state.repeat_index, state.repeats,
                          bool(state.tuning), tuple(float(i) for i in state.coil_current_amplitude_a),
                          state.frequency_hz, state.theta0_rad, state.planned_duration_s, state.setup)

    def send(self, command: Command) -> None:
        raise NotExciting("the bag backend replays a recording: it cannot excite")

    def coils_off_now(self) -> None:
        """A recording has no coils to switch."""

    def supply_to_zero_now(self) -> None:
        """A recording has no supply to set."""

    def stats(self) -> dict:
        return {"link": "finished" if self._finished else "replaying", "bag_path": self.path,
                "replayed_messages": self.replayed, "skipped_messages": sum(self.skipped.values()),
                **{f"skipped: {why}": n for why, n in self.skipped.items()}}

    def close(self) -> None:
        self._messages.close()
