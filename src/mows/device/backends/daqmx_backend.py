"""The paper's bench as the driver's device (:class:`mows.device.interface.Backend` ``nidaqmx``):
the fluxgates and the coils on an NI card through NI's ``nidaqmx``, the field supply (optional)
through SCPI (:mod:`mows.device.instruments.scpi`).

A thin edge over :mod:`mows.device.instruments.daq`: two continuous, hardware-timed input channels read in
blocks and stamped by their sample index (:class:`mows.device.clock.DeviceClock`); two output
channels on the same rate, started by the inputs' start trigger and never regenerated, written
``output_lead_s`` ahead of the newest input sample with the coils' waveforms, so that a coil
command for a sample beyond what is written applies exactly there. The stage is turned by hand
(``orientation: manual``): an orientation command is the operator's turn, confirmed before the
cycle was asked for, and is accepted at once.

A watchdog thread stands in for the serial device's: a host that stops reading for
``watchdog_s`` (a hung driver) has the outputs stopped (they idle at 0 V: the coils go off) and
the supply ramped to zero within its slew limit; the next read reports the link down.

``nidaqmx`` is imported when a backend is made, not before: without NI's runtime, the package or
the card, :func:`open_daqmx` says so in one line (:class:`DeviceUnavailable`).
"""

from __future__ import annotations

import importlib
import math
import threading
import time

import numpy as np

from mows.device.clock import DeviceClock
from mows.device.instruments.daq import CoilWaveforms, DaqDevice
from mows.device.instruments.scpi import ScpiSupply, SupplyError, SupplySchedule
from mows.device.interface import (
    Backend,
    CoilCommand,
    Command,
    CommandResult,
    FieldCurrentCommand,
    LinkEvent,
    check_coil_command,
    refuse_tones,
)
from mows.device.protocol.payloads import DeviceInfo
from mows.physics.coils import CurrentCap
from mows.physics.supply import RAMP_STEP_S
from mows.records.samples import SampleBlock

INPUT_BUFFER_S = 10.0  # the card's input buffer: a host late by less than this loses nothing


class DeviceUnavailable(OSError):
    """NI's runtime, the ``nidaqmx`` package or the card is missing, or the card refused the tasks."""


def import_nidaqmx():
    """NI's ``nidaqmx`` package; DeviceUnavailable, one line, when it is not installed."""
    try:
        return importlib.import_module("nidaqmx")
    except ImportError:
        raise DeviceUnavailable(
            "backend nidaqmx: the Python package nidaqmx is not installed (pip install nidaqmx==1.7.0)"
        ) from None


def _first_line(error: Exception) -> str:
    return (str(error).strip().splitlines() or [type(error).__name__])[0]


class DaqmxBackend(Backend):
    """The card's tasks (made by :func:`open_daqmx`), the coils' waveforms and the supply."""

    name = "nidaqmx"
    can_excite = True

    def __init__(self, daqmx, device: DaqDevice, cap: CurrentCap, supply: ScpiSupply | None = None):
        self.daqmx = daqmx
        self.device = device
        self.cap = CurrentCap(min(cap.limit_a, device.current_cap_a))
        self.supply = supply
        self.supply_schedule = SupplySchedule(supply.config.limits, device.sample_rate_hz) if supply else None
        self.supply_limits = supply.config.limits if supply else None
        self.clock = DeviceClock(device.sample_rate_hz)
        self.waveforms = CoilWaveforms(len(device.outputs), device.sample_rate_hz, device.amplifier_v_per_a)
        self._info = DeviceInfo(
            device.sample_rate_hz,
            2,
            len(device.outputs),
            device.range_t,
            device.resolution_t,
            self.cap.limit_a,
            math.inf,
        )
        self.next_index = 0  # the sample after the newest read
        self.stage_theta0_rad = math.nan  # where the operator turned the probe
        self.fault = ""  # why the card stopped, once it did
        self._fault_told = False  # the LinkEvent that says so has been handed out
        self.supply_readback_a = math.nan
        self._results: list[CommandResult] = []
        self._lock = threading.Lock()
        self._buffer = np.zeros((2, device.block_samples))
        self._ai, self._ao = self._tasks()
        self._reader = daqmx.stream_readers.AnalogMultiChannelReader(self._ai.in_stream)
        self._writer = daqmx.stream_writers.AnalogMultiChannelWriter(self._ao.out_stream, auto_start=False)
        self._write_ahead()  # the outputs start with data, before their trigger
        self._ao.start()
        self._ai.start()
        self._last_poll_s = time.monotonic()
        self._stop = threading.Event()
        self._watchdog = threading.Thread(target=self._watch, name="mows-daqmx-watchdog", daemon=True)
        self._watchdog.start()

    def _tasks(self):
        """The input and output tasks, configured (both closed again if the card refuses either)."""
        ai = self.daqmx.Task("mows_fluxgates")
        ao = self.daqmx.Task("mows_coils")
        try:
            self._configure(ai, ao)
        except BaseException:
            ai.close()
            ao.close()
            raise
        return ai, ao

    def _configure(self, ai, ao) -> None:
        constants, device = self.daqmx.constants, self.device
        for channel in device.inputs:
            ai.ai_channels.add_ai_voltage_chan(
                channel.physical_channel,
                terminal_config=constants.TerminalConfiguration[channel.terminal_config],
                min_val=-channel.range_v,
                max_val=channel.range_v,
            )
        ai.timing.cfg_samp_clk_timing(
            device.sample_rate_hz,
            sample_mode=constants.AcquisitionType.CONTINUOUS,
            samps_per_chan=round(INPUT_BUFFER_S * device.sample_rate_hz),
        )
        for output in device.outputs:
            ao.ao_channels.add_ao_voltage_chan(output.physical_channel, min_val=-output.range_v, max_val=output.range_v)
        # When the host stops writing the card underflows and stops: the coils go to zero, not stay on.
        ao.ao_channels.all.ao_idle_output_behavior = constants.AOIdleOutputBehavior.ZERO_VOLTS
        ao.timing.cfg_samp_clk_timing(
            device.sample_rate_hz,
            sample_mode=constants.AcquisitionType.CONTINUOUS,
            samps_per_chan=2 * (device.lead_samples + device.block_samples),
        )
        ao.triggers.start_trigger.cfg_dig_edge_start_trig(device.start_trigger)
        ao.out_stream.regen_mode = constants.RegenerationMode.DONT_ALLOW_REGENERATION

    @property
    def info(self) -> DeviceInfo:
        return self._info

    @property
    def command_lead_samples(self) -> int:
        return self.device.lead_samples + self.device.block_samples

    def _write_ahead(self) -> None:
        end = self.next_index + self.device.block_samples + self.device.lead_samples
        volts = self.waveforms.synthesise(end)
        if volts.shape[1]:
            self._writer.write_many_sample(np.ascontiguousarray(volts), timeout=self.device.read_timeout_s)

    def poll(self, timeout_s: float) -> list:
        with self._lock:
            self._last_poll_s = time.monotonic()
            items: list = list(self._results)
            self._results = []
            if self.fault:
                return items + self._fault_event()
            try:
                self._write_ahead()
                self._reader.read_many_sample(
                    self._buffer,
                    number_of_samples_per_channel=self.device.block_samples,
                    timeout=self.device.read_timeout_s,
                )
            except self.daqmx.errors.DaqError as error:
                self.fault = f"the card stopped: {_first_line(error)}"
                return items + self._fault_event()
            first = self.next_index
            self.next_index += self.device.block_samples
            field, saturated = self.device.field_t(self._buffer)
            items.append(SampleBlock(first, self.clock.stamp_ns(first), self.device.sample_rate_hz, field, saturated))
            items += self._supply_steps()
        return items

    def _supply_steps(self) -> list:
        """Write the supply's steps whose sample has come; read the current back after a ramp's last."""
        if self.supply is None or self.supply_schedule is None:
            return []
        due = self.supply_schedule.due(self.next_index)
        try:
            for current_a in due:
                self.supply.set_current_a(current_a)
            if due and not self.supply_schedule.ramping:
                self.supply_readback_a = self.supply.read_current_a()
        except SupplyError as error:
            self.fault = f"the supply failed: {error}"
            self.waveforms.off_now()
            return self._fault_event()
        return []

    def _fault_event(self) -> list[LinkEvent]:
        """The link down, once: the driver fails a running cycle on it."""
        told, self._fault_told = self._fault_told, True
        return [] if told else [LinkEvent(False, self.fault)]

    def _watch(self) -> None:
        while not self._stop.wait(RAMP_STEP_S):
            with self._lock:
                silent_s = time.monotonic() - self._last_poll_s
                if not self.fault and silent_s > self.device.watchdog_s:
                    self._trip(f"watchdog: no read for {silent_s:.1f} s: coils off, supply ramped to zero")

    def _trip(self, reason: str) -> None:
        """Outputs stopped (they idle at 0 V), the supply ramped down in host time."""
        self.fault = reason
        try:
            self._ao.stop()
        except self.daqmx.errors.DaqError:
            pass  # a card that stopped by itself has its outputs idle already
        if self.supply is None or self.supply_schedule is None:
            return
        try:
            for _, current_a in self.supply.config.limits.ramp(self.supply_schedule.current_a, 0.0):
                self.supply.set_current_a(current_a)
                self.supply_schedule.current_a = current_a
                time.sleep(RAMP_STEP_S)
        except SupplyError as error:
            self.fault += f"; THE SUPPLY DID NOT RAMP TO ZERO: {error}"

    def send(self, command: Command) -> None:
        command = refuse_tones(command, "DAQmx device")
        with self._lock:
            if isinstance(command, CoilCommand):
                check_coil_command(command, self._info, self.cap.limit_a)
                applied = self.waveforms.schedule(command.at_sample_index, command.amplitudes_a, command.frequency_hz)
            elif isinstance(command, FieldCurrentCommand):
                if self.supply_schedule is None:
                    self._results.append(
                        CommandResult(command.command_id, False, reason="no field supply (supply: none)")
                    )
                    return
                applied = self.supply_schedule.ramp(command.at_sample_index, self.next_index, command.current_a)
            else:
                if self.waveforms.coils_on:
                    self._results.append(CommandResult(command.command_id, False, reason="the coils are on"))
                    return
                self.stage_theta0_rad = command.theta0_rad  # turned by hand before the cycle was asked for
                applied = max(command.at_sample_index, self.next_index)
            self._results.append(CommandResult(command.command_id, True, applied))

    def coils_off_now(self) -> None:
        with self._lock:
            self.waveforms.off_now()

    def supply_to_zero_now(self) -> None:
        with self._lock:
            if self.supply_schedule is not None:
                self.supply_schedule.to_zero(self.next_index)

    def stats(self) -> dict:
        values: dict = {
            "link": "down" if self.fault else "nidaqmx",
            "device_coils_on": self.waveforms.coils_on,
            "samples_read": self.next_index,
            "stage": "manual",
        }
        if self.fault:
            values["fault"] = self.fault
        if self.supply is not None and self.supply_schedule is not None:
            values.update(
                supply=self.supply.identity,
                supply_target_a=self.supply_schedule.target_a,
                supply_readback_a=self.supply_readback_a,
            )
        return values

    def close(self) -> None:
        """Coils off, the supply ramped to zero while the card streams on, then the tasks and the
        supply released."""
        self._stop.set()
        self._watchdog.join()
        self.coils_off_now()
        self.supply_to_zero_now()
        while self.supply_schedule is not None and self.supply_schedule.ramping and not self.fault:
            self.poll(self.device.read_timeout_s)
        self.poll(self.device.read_timeout_s)  # the zeros of the switch-off reach the card
        try:
            for task in (self._ao, self._ai):
                task.stop()
                task.close()
        finally:
            if self.supply is not None:
                self.supply.close()


def open_daqmx(device: DaqDevice, cap: CurrentCap, supply: ScpiSupply | None = None, daqmx=None) -> DaqmxBackend:
    """The backend on the card of ``device`` (``daqmx``: the ``nidaqmx`` module or a stand-in with
    its API; default: NI's, imported now). DeviceUnavailable, in one line, when the package, NI's
    runtime or the card is missing, or the card refuses the tasks."""
    daqmx = daqmx or import_nidaqmx()
    try:
        return DaqmxBackend(daqmx, device, cap, supply)
    except daqmx.errors.DaqNotFoundError:
        raise DeviceUnavailable(
            "backend nidaqmx: NI-DAQmx (NI's driver runtime) is not installed on this machine: install it "
            "from ni.com (on Linux: python -m nidaqmx installdriver)"
        ) from None
    except daqmx.errors.DaqError as error:
        raise DeviceUnavailable(f"backend nidaqmx: card {device.device_name!r}: {_first_line(error)}") from None
