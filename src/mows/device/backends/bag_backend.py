"""A recorded bag as the driver's device (:class:`mows.device.interface.Backend` ``bag``): the
driver's own rosbag2 recordings replayed through the driver's path at a multiple of real time."""

from __future__ import annotations

import collections
import itertools
import math
import os
import time

import numpy as np

from mows.device.cycle.phases import Phase, PhaseEvent, SupplyEvent
from mows.device.interface import Backend, Command, LinkEvent, NotExciting
from mows.device.protocol.payloads import DeviceInfo
from mows.device.recording import bags
from mows.records import stamps
from mows.records.samples import SampleBlock

RAW_TYPE = "mows_msgs/msg/MagnetometerBlock"
EXCITATION_TYPE = "mows_msgs/msg/ExcitationState"
SUPPLY_TYPE = "mows_msgs/msg/SupplyState"  # recorded since the driver publishes mows/supply (older bags lack it)


class BagBackend(Backend):
    """A recorded rosbag2 bag (the driver's own recordings: MagnetometerBlock, ExcitationState
    and SupplyState messages, on whatever topics) replayed through the driver's path.

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
        self._messages = (m for m in bags.read_bag(path) if m.msgtype in (RAW_TYPE, EXCITATION_TYPE, SUPPLY_TYPE))
        self._ahead: collections.deque[bags.BagMessage] = collections.deque()
        first_raw = self._first_raw()
        block = first_raw.message
        if not (math.isfinite(block.sample_rate_hz) and block.sample_rate_hz > 0 and block.channels):
            raise ValueError(
                f"the bag {self.path} starts with a block of sample rate {block.sample_rate_hz!r} Hz "
                f"and {len(block.channels)} channels: nothing to replay"
            )
        self._info = DeviceInfo(
            block.sample_rate_hz, len(block.channels), 0, block.range_t, block.resolution_t, 0.0, math.inf
        )
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
        items: list[SampleBlock | PhaseEvent | SupplyEvent | LinkEvent] = []
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
        replay = {RAW_TYPE: self._chunk, EXCITATION_TYPE: self._event, SUPPLY_TYPE: supply_event}[message.msgtype]
        try:
            item = replay(message.message)
        except ValueError as nonsense:
            reason = str(nonsense)
            self.skipped[reason] = self.skipped.get(reason, 0) + 1
            return []
        self.replayed += 1
        return [item]

    def _chunk(self, block) -> SampleBlock:
        lengths = {len(c.field_t) for c in block.channels} | {len(c.saturated) for c in block.channels}
        if (
            len(lengths) != 1
            or len(block.channels) != self.info.n_channels
            or block.sample_rate_hz != self.info.sample_rate_hz
        ):
            raise ValueError("a block whose channels or rate do not match the recording's")
        stamp = stamps.nanoseconds(block.header.stamp)
        self._anchor = (block.first_sample_index, stamp)
        return SampleBlock(
            block.first_sample_index,
            stamp,
            self.info.sample_rate_hz,
            np.stack([c.field_t for c in block.channels], axis=1),
            np.stack([c.saturated for c in block.channels], axis=1).astype(bool),
        )

    def _event(self, state) -> PhaseEvent:
        if state.phase not in set(Phase):
            raise ValueError(f"an excitation state with the unknown phase {state.phase}")
        stamp = stamps.nanoseconds(state.header.stamp)
        index = self._anchor[0] + round((stamp - self._anchor[1]) * self.info.sample_rate_hz / 1e9)
        return PhaseEvent(
            Phase(state.phase),
            index,
            stamp,
            state.cycle_id,
            state.repeat_index,
            state.repeats,
            bool(state.tuning),
            tuple(float(i) for i in state.coil_current_amplitude_a),
            state.frequency_hz,
            state.theta0_rad,
            state.planned_duration_s,
            state.setup,
            probe_ids=tuple(int(i) for i in state.probe_ids),
            probe_frequency_hz=tuple(float(f) for f in state.probe_frequency_hz),
            probe_theta0_rad=tuple(float(a) for a in state.probe_theta0_rad),
        )

    def send(self, command: Command) -> None:
        raise NotExciting("the bag backend replays a recording: it cannot excite")

    def coils_off_now(self) -> None:
        """A recording has no coils to switch."""

    def supply_to_zero_now(self) -> None:
        """A recording has no supply to set."""

    def stats(self) -> dict:
        return {
            "link": "finished" if self._finished else "replaying",
            "bag_path": self.path,
            "replayed_messages": self.replayed,
            "skipped_messages": sum(self.skipped.values()),
            **{f"skipped: {why}": n for why, n in self.skipped.items()},
        }

    def close(self) -> None:
        self._messages.close()


def supply_event(state) -> SupplyEvent:
    """A recorded ``mows_msgs/SupplyState`` as the session's event."""
    if not math.isfinite(state.current_a):
        raise ValueError(f"a supply state with the current {state.current_a!r} A")
    return SupplyEvent(
        state.sample_index, stamps.nanoseconds(state.header.stamp), state.current_a, bool(state.ramping), state.reason
    )
