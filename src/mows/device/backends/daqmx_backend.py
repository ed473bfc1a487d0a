"""The paper's bench as the driver's device (:class:`mows.device.interface.Backend` ``nidaqmx``):
the fluxgates and the coils on an NI card through NI's ``nidaqmx``, the field supply (optional)
through SCPI (:mod:`mows.device.instruments.scpi`).

A thin edge over :mod:`mows.device.instruments.daq`: two continuous, hardware-timed input channels read in
blocks and stamped by their sample index (:class:`mows.device.clock.DeviceClock`); two output
channels on the same rate (the rate the card reads back: a rate its timebase does not divide is
refused, not coerced), started by the inputs' start trigger and never regenerated, written
``output_lead_s`` ahead of the newer of the newest input sample and the sample the card is
generating, so that a host stalled for less than the lead (2 s on the paper's bench, sized for
the stalls of a loaded machine; :attr:`DaqDevice.stall_survived_s`) never underflows them. A
host stalled for longer finds them underflowed (−200290): a fault, as below, never a silent
loss. The lead holds only what was commanded: the coils' drives with their switch-offs, zeros
elsewhere; a coil command for a sample beyond what is written applies exactly there. A host
behind its card catches up in reads of several blocks (``CATCH_UP_BLOCKS``), each cheaper per
sample than a block's, so that a loaded host does not fall further behind. The stage is turned
by hand (``orientation: manual``): an orientation command is accepted only as the operator's
turn, confirmed before the cycle was asked for (``by_hand``), and refused otherwise, since
nothing here turns the probe; ``turned`` hears it (the simulated bench's operator turns its
simulated probe there). The supply's I/O runs on a thread of its own, each
exchange under a deadline (:mod:`mows.device.backends.bench_supply`).

A card error (the outputs underflowed, the inputs overran, the card went away; every task's error
told, not only the first) is a fault, never a latch for the session: the tasks are closed (the
outputs idle at 0 V: the coils go off), the queued drives dropped, the supply ramped to zero in
host time and switched off, and the link reported down with the reason (a running cycle fails);
then the tasks are made and armed again, starting with the coils off, at once and, while the card
refuses, every ``read_timeout_s``. The link comes back up with a :class:`DeviceFault` that
carries the reason to the driver's /diagnostics; the stream's sample index jumps by the time the
card was down (the blocks' gap). The supply is switched on again, at zero, before its next ramp.

A switch-off (a cancel, an emergency stop) does not wait for the lead: a drive written ahead is
cut by stopping the card and arming it again, the coils off (:meth:`DaqmxBackend.coils_off_now`).
A watchdog thread stands in for the serial device's: a host that has not read a block for
``watchdog_s`` (a hung driver, or one whose every poll fails) faults the card as above; the next
poll re-arms it. The threads that feed the card (the one that polls it, the supply's, the
watchdog) run under SCHED_FIFO at ``realtime_priority`` where allowed (:mod:`.realtime`).

``nidaqmx`` is imported when a backend is made, not before: without NI's runtime, the package or
the card, :func:`open_daqmx` says so in one line (:class:`DeviceUnavailable`).
"""

from __future__ import annotations

import contextlib
import math
import threading
import time
from collections.abc import Callable

import numpy as np

from mows.device.backends.bench_supply import NOT_READ, Readback, SupplyLine
from mows.device.backends.daqmx_tasks import (
    TASK_NAMES,
    DeviceUnavailable,
    close_tasks,
    configure_tasks,
    first_line,
    import_nidaqmx,
    read_waiting,
)
from mows.device.backends.realtime import Priority
from mows.device.clock import DeviceClock
from mows.device.instruments.daq import CoilWaveforms, DaqDevice
from mows.device.instruments.scpi import ScpiSupply
from mows.device.instruments.supply_schedule import SupplySchedule
from mows.device.interface import (
    Backend,
    CoilCommand,
    Command,
    CommandResult,
    DeviceFault,
    FieldCurrentCommand,
    LinkEvent,
    OrientationCommand,
    check_coil_currents,
    one_tone,
)
from mows.device.protocol.payloads import DeviceInfo
from mows.physics.coils import CurrentCap
from mows.physics.supply import RAMP_STEP_S
from mows.records.samples import SampleBlock

CATCH_UP_BLOCKS = 20  # the most blocks read at once by a host behind its card (0.5 s on the paper's bench)


class DaqmxBackend(Backend):
    """The card's tasks, the coils' waveforms and the supply (made by :func:`open_daqmx`)."""

    name = "nidaqmx"
    can_excite = True

    def __init__(
        self,
        daqmx,
        device: DaqDevice,
        cap: CurrentCap,
        supply: ScpiSupply | None = None,
        held: contextlib.ExitStack | None = None,
        turned: Callable[[float], None] | None = None,
    ):
        self.daqmx = daqmx
        self._turned = turned
        self.held = held or contextlib.ExitStack()  # released after the card and the supply (a simulated card's seam)
        self.device = device
        self.cap = CurrentCap(min(cap.limit_a, device.current_cap_a))
        self.supply = supply
        self.priority = priority = Priority(device.realtime_priority)  # of the threads that feed the card
        self.supply_line = SupplyLine(supply, 2.0 * supply.config.timeout_s, priority.raise_thread) if supply else None
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
        self.catch_up_blocks = CATCH_UP_BLOCKS
        self.stage_theta0_rad = math.nan  # where the operator turned the probe
        self.fault = ""  # why the card is down, while it is
        self.card_faults = 0
        self.last_card_fault = ""
        self._off_at_zero = False  # an emergency stop's ramp to zero: the output off once it ends
        self._results: list[CommandResult] = []
        self._told: list[LinkEvent | DeviceFault] = []  # not yet handed out
        self._lock = threading.Lock()
        self._buffer = np.zeros((2, device.block_samples))
        self._tasks: list = []  # the input and the output task, while armed
        self._origin = 0  # the stream's index of the card's sample 0
        self._rearm_at_s = 0.0
        self._arm(0)
        self._last_read_s = time.monotonic()
        self._stop = threading.Event()
        self._watchdog = threading.Thread(target=self._watch, name="mows-daqmx-watchdog", daemon=True)
        self._watchdog.start()

    # --- the card's tasks ----------------------------------------------------------------------
    def _arm(self, first_index: int) -> None:
        """Make and configure the tasks, write the outputs' first samples (coils off) and start them
        on the inputs' trigger, the card's sample 0 being the stream's ``first_index``. Whatever
        was made is closed again when any step fails."""
        self.next_index = self._origin = first_index
        self.waveforms.restart(first_index)
        tasks: list = []
        try:
            for name in TASK_NAMES:
                tasks.append(self.daqmx.Task(name))
            ai, ao = tasks
            configure_tasks(self.daqmx, self.device, ai, ao)
            self._reader = self.daqmx.stream_readers.AnalogMultiChannelReader(ai.in_stream)
            self._writer = self.daqmx.stream_writers.AnalogMultiChannelWriter(ao.out_stream, auto_start=False)
            self._tasks = tasks
            self._write_ahead()  # the outputs start with data, before their trigger
            ao.start()
            ai.start()
        except BaseException:
            self._tasks = []
            close_tasks(self.daqmx, tasks)
            raise

    @property
    def info(self) -> DeviceInfo:
        return self._info

    @property
    def command_lead_samples(self) -> int:
        return self.device.lead_samples + self.device.block_samples

    def _write_ahead(self) -> None:
        """The outputs written ``output_lead_s`` ahead of the newest block read or of the sample the
        card generates now, whichever is later (a host catching up after a stall has both)."""
        end = max(self.next_index + self.device.block_samples, self._generated()) + self.device.lead_samples
        volts = self.waveforms.synthesise(end)
        if volts.shape[1]:
            self._writer.write_many_sample(np.ascontiguousarray(volts), timeout=self.device.read_timeout_s)

    def _generated(self) -> int:
        """The stream's index of the sample the card generates now."""
        return self._origin + self._tasks[1].out_stream.total_samp_per_chan_generated

    # --- the stream ----------------------------------------------------------------------------
    def poll(self, timeout_s: float) -> list:
        self.priority.raise_thread()  # the thread that feeds the card: the driver's stream thread
        with self._lock:
            items: list = list(self._results)
            self._results = []
            if not self.fault:
                items += self._stream()
            if self.fault and time.monotonic() >= self._rearm_at_s:
                self._rearm()
            items += self._told
            self._told = []
            waiting = bool(self.fault) and not items
        if waiting:  # the card is away: no busy loop while it stays so
            time.sleep(min(timeout_s, self.device.read_timeout_s))
        return items

    def _stream(self) -> list:
        """The outputs written ahead, the blocks read and the supply's steps that are due; on a
        card error, the fault, with both tasks' errors (an input overrun is not hidden behind the
        outputs')."""
        errors = []
        try:
            # NI's check of a continuous generation: it raises the error that stopped it. A host
            # behind the card may have nothing new to write, and only a write would say so.
            if self._tasks[1].is_task_done():
                errors.append("outputs: the generation stopped")
            else:
                self._write_ahead()
        except self.daqmx.errors.DaqError as error:
            errors.append(f"outputs: {first_line(error)}")
        try:
            volts = read_waiting(self._tasks[0], self._reader, self.device, self._buffer, self.catch_up_blocks)
        except self.daqmx.errors.DaqError as error:
            errors.append(f"inputs: {first_line(error)}")
        if errors:
            self._fault("the card stopped: " + "; ".join(errors))
            return []
        self._last_read_s = time.monotonic()
        field, saturated = self.device.field_t(volts)
        n, blocks = self.device.block_samples, []
        for start in range(0, volts.shape[1], n):
            first, self.next_index, rows = self.next_index, self.next_index + n, slice(start, start + n)
            stamp_ns = self.clock.stamp_ns(first)
            blocks.append(SampleBlock(first, stamp_ns, self.device.sample_rate_hz, field[rows], saturated[rows]))
        return [*blocks, *self._supply_steps()]

    def _supply_steps(self) -> list:
        """Hand the supply's steps whose sample has come to its line (written there, off this
        thread), the last of a ramp to be read back once settled; a failure of the supply (an
        error, an exchange past its deadline, an output that went off by itself) is a fault."""
        if self.supply_line is None or self.supply_schedule is None:
            return []
        due = self.supply_schedule.due(self.next_index)
        for k, current_a in enumerate(due):
            last = k == len(due) - 1 and not self.supply_schedule.ramping
            self.supply_line.step(current_a, self.supply_schedule.last_index, last)
        if due and not self.supply_schedule.ramping and self._off_at_zero:
            self._off_at_zero = False
            self.supply_line.switch_off()  # the emergency stop's ramp has reached zero
        if failure := self.supply_line.failure():
            self._fault(failure)
        return []

    def _fault(self, reason: str) -> None:
        """The card down: its tasks closed (the outputs idle at 0 V: the coils off), the drives
        dropped, the supply ramped to zero and switched off, the link down with ``reason``."""
        self.waveforms.off_now()
        close_tasks(self.daqmx, self._tasks)
        self._tasks = []
        self.fault = self.last_card_fault = reason + self._supply_safe()
        self.card_faults += 1
        self._rearm_at_s = time.monotonic()
        self._told.append(LinkEvent(False, self.fault))

    def _supply_safe(self) -> str:
        """Ramp the supply to zero in host time from the last current it accepted, within its slew
        limit, and switch its output off; what went wrong, for the fault's reason."""
        if self.supply_line is None or self.supply_schedule is None:
            return ""
        end = self.supply_schedule.to_zero(self.next_index)
        self.supply_schedule.due(end + 1)  # walked in host time: the card's samples have stopped
        self._off_at_zero = False
        return "".join(f"; {problem}" for problem in self.supply_line.make_safe(self.supply_schedule.last_index))

    def _rearm(self) -> None:
        """Arm the card again, the coils off; the link up and the fault told to the driver (its
        /diagnostics), or the next try in ``read_timeout_s``."""
        if refused := self._arm_on():
            self._rearm_at_s = time.monotonic() + self.device.read_timeout_s
            self.last_card_fault = f"{self.fault}; re-arming: {refused}"
            return
        reason, self.fault = self.fault, ""
        self._told += [LinkEvent(True, f"the card re-armed after: {reason}"), DeviceFault(reason)]

    def _arm_on(self) -> str:
        """Arm the card, its index on from the samples it took since the last read; '' or why not."""
        try:
            self._arm(self.next_index + round((time.monotonic() - self._last_read_s) * self.device.sample_rate_hz))
        except self.daqmx.errors.DaqError as error:
            return first_line(error)
        self._last_read_s = time.monotonic()
        return ""

    def _watch(self) -> None:
        self.priority.raise_thread()
        while not self._stop.wait(RAMP_STEP_S):
            with self._lock:
                silent_s = time.monotonic() - self._last_read_s
                if not self.fault and silent_s > self.device.watchdog_s:
                    self._fault(f"watchdog: no read for {silent_s:.1f} s: coils off, supply ramped to zero")

    # --- commands ------------------------------------------------------------------------------
    def send(self, command: Command) -> None:
        if isinstance(command, CoilCommand):
            frequency_hz, amplitudes = one_tone(command, "DAQmx device", self._info.n_coils)
        with self._lock:
            if self.fault:
                self._results.append(CommandResult(command.command_id, False, reason=f"the card is down: {self.fault}"))
                return
            if isinstance(command, CoilCommand):
                check_coil_currents(amplitudes, self._info, self.cap.limit_a)
                applied = self.waveforms.schedule(command.at_sample_index, amplitudes, frequency_hz)
            elif isinstance(command, FieldCurrentCommand):
                if self.supply_schedule is None:
                    self._results.append(
                        CommandResult(command.command_id, False, reason="no field supply (supply: none)")
                    )
                    return
                applied = self.supply_schedule.ramp(command.at_sample_index, self.next_index, command.current_a)
                self._off_at_zero = False
            else:
                if (refused := self._turn_refused(command)) is not None:
                    self._results.append(CommandResult(command.command_id, False, reason=refused))
                    return
                self.stage_theta0_rad = command.theta0_rad  # turned by hand before the cycle was asked for
                if self._turned is not None:
                    self._turned(command.theta0_rad)
                applied = max(command.at_sample_index, self.next_index)
            self._results.append(CommandResult(command.command_id, True, applied))

    def _turn_refused(self, command: OrientationCommand) -> str | None:
        if self.waveforms.coils_on:
            return "the coils are on"
        if not command.by_hand:
            return (
                f"this bench's stage is turned by hand: a cycle at θ0 = {command.theta0_rad:.4g} rad needs the "
                "operator's turn first (orientation: manual in the mapper and the calibrator)"
            )
        return None

    def coils_off_now(self) -> None:
        """The coils off at once: the queued drives dropped, and a drive already written ahead
        (up to ``output_lead_s``) cut by stopping the card, whose outputs idle at 0 V, and arming
        it again with the coils off; the stream goes on after a gap of the samples it took meanwhile."""
        with self._lock:
            self.waveforms.off_now()
            try:
                driving = bool(self._tasks) and not self.fault and self.waveforms.driven_until > self._generated()
            except self.daqmx.errors.DaqError:  # the card stopped, its outputs idle at 0 V: the next poll says why
                return
            if driving:
                close_tasks(self.daqmx, self._tasks)
                self._tasks = []
                if refused := self._arm_on():
                    self._fault(f"the card stopped to switch the coils off: re-arming: {refused}")

    def supply_to_zero_now(self) -> None:
        """The ramp to zero, the output switched off at its end; a supply already switched off
        stays off (its waiting ramp dropped), not switched on again to be ramped."""
        with self._lock:
            if self.supply_schedule is not None and self.supply_line is not None and self.supply_line.off:
                self.supply_schedule.drop()
            elif self.supply_schedule is not None:
                self.supply_schedule.to_zero(self.next_index)
                self._off_at_zero = True

    def stats(self) -> dict:
        values: dict = {
            "link": "down" if self.fault else "nidaqmx",
            "device_coils_on": self.waveforms.coils_on,
            "samples_read": self.next_index,
            "stage": "manual",
            "card_faults": self.card_faults,
            "last_card_fault": self.last_card_fault,
            "realtime": self.priority.state,
        }
        if self.supply_line is not None and self.supply_schedule is not None:
            values.update(self.supply_line.stats(self.supply_schedule.target_a))
        return values

    @property
    def supply_readback(self) -> Readback:
        """The supply's last read-back, stamped with the step it follows."""
        return self.supply_line.readback if self.supply_line is not None else NOT_READ

    def close(self) -> None:
        """Coils off, the supply ramped to zero and switched off while the card streams on, and
        read back once settled; then the tasks and the supply released (every output off and
        read back), each whatever the others did, and last what the backend held. SupplyError
        when the supply's release failed, after all of it was tried. Once closed, nothing more."""
        if self._stop.is_set():
            return
        self._stop.set()
        self._watchdog.join()
        try:
            self.coils_off_now()
            self.supply_to_zero_now()
            polls = 0
            while self.supply_pending and not self.fault:
                self.poll(self.device.read_timeout_s)
                polls += 1
                if polls * self.device.block_s > 60.0:  # a ramp from the cap takes seconds, not this
                    with self._lock:
                        self._fault("close: the supply's ramp to zero did not end")
            if not self.fault:
                self.poll(self.device.read_timeout_s)  # the zeros of the switch-off reach the card
        finally:
            try:
                with self._lock:
                    close_tasks(self.daqmx, self._tasks)
                    self._tasks = []
            finally:
                with self.held:
                    self.priority.restore()
                    if self.supply_line is not None:
                        self.supply_line.close()

    @property
    def supply_pending(self) -> bool:
        """A ramp of the supply, its steps' writes or its read-back, still to come."""
        schedule, line = self.supply_schedule, self.supply_line
        return schedule is not None and line is not None and (schedule.ramping or line.busy)

    def closed_state(self) -> str:
        """The supply as it read back, settled, after its ramp to zero and switch-off on close."""
        return self.supply_line.closed_state() if self.supply_line is not None else ""


def open_daqmx(
    device: DaqDevice,
    cap: CurrentCap,
    supply: ScpiSupply | None = None,
    held: contextlib.ExitStack | None = None,
    turned: Callable[[float], None] | None = None,
) -> DaqmxBackend:
    """The backend on the card of ``device``, through NI's ``nidaqmx`` (imported now), holding
    ``held`` until it is closed; ``turned`` hears each turn of the stage (:class:`DaqmxBackend`).
    DeviceUnavailable, in one line, when the package, NI's runtime or the card is missing, or the
    card refuses the tasks."""
    daqmx = import_nidaqmx()
    try:
        return DaqmxBackend(daqmx, device, cap, supply, held, turned)
    except daqmx.errors.DaqNotFoundError:
        raise DeviceUnavailable(
            "backend nidaqmx: NI-DAQmx (NI's driver runtime) is not installed on this machine: install it "
            "from ni.com (Ubuntu, RHEL or openSUSE; not Debian: docs/hardware.md)"
        ) from None
    except daqmx.errors.DaqError as error:
        raise DeviceUnavailable(f"backend nidaqmx: card {device.device_name!r}: {first_line(error)}") from None
