"""A device on a serial port as the driver's device (:class:`mows.device.interface.Backend`
``serial``): the driver's commands turned into frames for :class:`mows.device.serial.link.SerialLink`
and its frames turned into sample blocks, command results and device faults."""

from __future__ import annotations

import threading

from mows.device.interface import (
    Backend,
    CoilCommand,
    Command,
    CommandResult,
    DeviceFault,
    FieldCurrentCommand,
    LinkEvent,
    NotExciting,
    check_coil_currents,
    one_tone,
)
from mows.device.protocol.payloads import Ack, Coils, DeviceInfo, FieldCurrent, Orientation, Samples, Status
from mows.device.serial.link import SerialLink
from mows.physics.coils import CurrentCap
from mows.records.samples import SampleBlock

COMMAND_LEAD_S = 0.05  # serial commands are scheduled this far ahead of the newest sample


class SerialBackend(Backend):
    """A device on a serial port (:class:`mows.device.serial.link.SerialLink`).

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
        self._lock = threading.Lock()  # sending and registering a command is one step

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
        return [
            SampleBlock(
                body.first_sample_index,
                timestamp_ns,
                info.sample_rate_hz,
                body.counts * info.resolution_t,
                body.saturated,
            )
        ]

    def _result(self, ack: Ack) -> list[CommandResult]:
        with self._lock:
            command_id = self._pending.pop(ack.command_sequence, None)
        if command_id is None:
            return []  # an answer to a command of an earlier connection
        return [
            CommandResult(
                command_id, ack.accepted, ack.applied_sample_index, "" if ack.accepted else f"device: {ack.reason}"
            )
        ]

    def send(self, command: Command) -> None:
        if self.info is None:
            raise NotExciting("the device has not described itself yet")
        body: Coils | Orientation | FieldCurrent
        if isinstance(command, CoilCommand):
            frequency_hz, amplitudes = one_tone(command, "serial device", self.info.n_coils)
            check_coil_currents(amplitudes, self.info, self.cap.limit_a)
            body = Coils(0, command.at_sample_index, frequency_hz, amplitudes)
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
            values.update(
                device_coils_on=s.coils_on,
                device_watchdog_trips=s.watchdog_trips,
                device_dropped_frames=s.dropped_frames,
                device_rejected_frames=s.rejected_frames,
            )
        return values

    def close(self) -> None:
        self.coils_off_now()
        self.supply_to_zero_now()
        self.link.close()
