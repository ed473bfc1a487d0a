"""The paper's NI card simulated under NI's own ``nidaqmx`` package: the tests and ``mows
check-hardware --simulate`` drive :class:`nidaqmx.Task`, its channels, timing, triggers and
stream readers and writers as they are, and only the package's lowest layer, the interpreter that
calls NI's C library (``nidaqmx._library_interpreter.LibraryInterpreter``, which
``nidaqmx.utils._select_interpreter`` makes for every task), is replaced by
:class:`mows.device.simulated.daqmx_interpreter.SimulatedInterpreter` on this card
(:meth:`SimulatedCard.installed`). Every attribute path, argument, constant and error class the
backend meets is NI's.

The card keeps wall-clock time: from the inputs' start trigger its sample clock advances with
``time.monotonic``, not with the reads. A host that reads late finds the samples waiting, up to
the input buffer; later than that the inputs overrun (−200279, ``SAMPLES_NO_LONGER_AVAILABLE``).
The outputs generate what was written and never regenerate: when the clock passes the last sample
written they stop (−200290, ``GEN_STOPPED_TO_PREVENT_REGEN_OF_OLD_SAMPLES``, NI's code for a
non-regenerating output the host did not keep fed) and idle at 0 V. A card pulled out
(:meth:`SimulatedCard.unplug`) answers −201003 (``DEV_CANNOT_BE_ACCESSED``) until it is back.

It holds the calls to what the bench requires of them, with NI's error codes: channels on the
card's terminals within its ranges; continuous hardware timing; the outputs started before the
inputs, on the inputs' start trigger, at their rate, with data written first, regeneration off and
0 V when idle; writes within the output buffer and its range; named tasks unique while open. Its
sample clock is its 100 MHz timebase divided by an integer: a rate it does not divide is coerced
to the next one above, as NI's cards do, and read back so.

What the outputs generate is what the amplifiers feed the coils: the card reads each drive back
from the volts (the sinusoid's frequency from three samples, its amplitude from one) and gives it
to :class:`mows.sim.simulator.SimulatedDevice` at its exact sample; what the inputs read is the
simulator's fluxgates in volts, the supply's current (a callable, e.g. the pyvisa-sim supply's)
applied before each read. The device's samples run on with the wall clock while the card is
stopped (coils off), so that a re-armed card finds the probe where time has taken it.

Why this module is over 450 lines: one card under one lock. Its clock, its tasks and the rules it
holds their calls to share that state; the interpreter that speaks NI's calls is apart.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import re
import threading
import time
from collections.abc import Callable, Iterator

import nidaqmx._library_interpreter
import numpy as np
from nidaqmx.constants import AcquisitionType, AOIdleOutputBehavior, RegenerationMode
from nidaqmx.error_codes import DAQmxErrors
from nidaqmx.errors import DaqError

from mows.device.simulated.daqmx_interpreter import SimulatedInterpreter, daq_error
from mows.sim.simulator import SimulatedDevice

MAX_RATE_HZ = 2.0e6  # the PCIe-6363's aggregate input rate
TIMEBASE_HZ = 100.0e6  # its sample clock's timebase: a rate is this divided by an integer
AI_RANGE_V = 10.0
AO_RANGE_V = 10.0
DRIVE_TOLERANCE_V = 1e-6  # a drive's samples follow its sinusoid to this, or the card refuses


@dataclasses.dataclass
class _Task:
    """One task on the card: its channels ((terminal, range V)), timing and state."""

    name: str
    kind: str = ""  # "ai" or "ao" once a channel is added
    channels: list[tuple[str, float]] = dataclasses.field(default_factory=list)
    rate_hz: float = 0.0
    buffer_samples: int = 0
    trigger: str = ""
    regen_mode: int = RegenerationMode.ALLOW_REGENERATION.value
    idle_behavior: int = AOIdleOutputBehavior.MAINTAIN_EXISTING_VALUE.value
    running: bool = False
    error: DaqError | None = None  # the error that stopped it, raised again until it is stopped
    position: int = 0  # inputs: the next sample to read; outputs: samples written since start


class SimulatedCard:
    """The simulated ``device`` wired to a card named after ``inputs``: fluxgate k on
    ``inputs[k]``, coil k's amplifier on ``outputs[k]`` with ``amplifier_v_per_a``; the fluxgates
    give ``sensitivity_v_per_t``. ``supply_current_a``: the field supply's present current, read
    before each block (None: the scenario's stays). ``clock``: the wall clock, s."""

    def __init__(
        self,
        device: SimulatedDevice,
        inputs=("Dev1/ai0", "Dev1/ai1"),
        outputs=("Dev1/ao0", "Dev1/ao1"),
        amplifier_v_per_a: float = 1.0,
        sensitivity_v_per_t: float = 1.0e6,
        supply_current_a: Callable[[], float] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.device = device
        self.inputs, self.outputs = tuple(inputs), tuple(outputs)
        self.device_name = self.inputs[0].split("/")[0]
        self.amplifier_v_per_a = amplifier_v_per_a
        self.sensitivity_v_per_t = sensitivity_v_per_t
        self.supply_current_a = supply_current_a
        self.clock = clock
        self.present = True
        self.timebase_hz = TIMEBASE_HZ
        self.tasks: dict[int, _Task] = {}  # by handle, while open
        self.made: list[_Task] = []  # every task ever made, in order
        self.drives: list[tuple[int, tuple, float]] = []  # (on sample, amplitudes A, Hz): what the coils got
        self.offs: list[int] = []  # the samples the coils went off at
        self.underflows = 0
        self.overruns = 0
        self.longest_write_gap_s = 0.0  # the longest the host left the generating outputs unfed, s
        self._last_write_s = 0.0  # the outputs' trigger or their last write since
        self._lock = threading.RLock()
        self._handles = 0
        self._world_start_s = math.nan  # the first trigger: the device's sample 0 is the card's first
        self._start_s = math.nan  # when the inputs' start trigger fired
        self._stopped_at = 0  # the samples the inputs had taken when they stopped
        self._base = 0  # the device sample of the card's sample 0 since that trigger
        self._pending = np.zeros((len(self.outputs), 0))  # output volts written before the trigger
        self._ao = np.zeros((len(self.outputs), 0))  # output volts not yet generated, by device sample
        self._ao_first = 0  # the device sample of self._ao's first column
        self._ao_end: int | None = None  # the device sample the outputs stopped at (0 V from there)
        self._drive: tuple[int, np.ndarray, float] | None = None  # the present drive (on, volts, ω)

    # --- the seam --------------------------------------------------------------------------
    def interpreter(self) -> SimulatedInterpreter:
        return SimulatedInterpreter(self)

    @contextlib.contextmanager
    def installed(self) -> Iterator[SimulatedCard]:
        """NI's package drives this card while inside: every new task's interpreter is this card's."""
        seam = nidaqmx._library_interpreter
        original = seam.LibraryInterpreter
        seam.LibraryInterpreter = self.interpreter
        try:
            yield self
        finally:
            seam.LibraryInterpreter = original

    # --- the bench ---------------------------------------------------------------------------
    def turn_probe(self, theta0_rad: float) -> None:
        """The operator turns the stage (the coils must be off)."""
        with self._lock:
            self.device.set_orientations([theta0_rad])

    def unplug(self) -> None:
        """The card is gone: its tasks fail and stop, the coils' amplifiers get 0 V."""
        with self._lock:
            self._advance()
            self.present = False
            for task in self.tasks.values():
                if task.running:
                    gone = daq_error(
                        DAQmxErrors.DEV_CANNOT_BE_ACCESSED, read=task.kind == "ai", write=task.kind == "ao"
                    )
                    self._stop(task, gone)

    def plug_in(self) -> None:
        with self._lock:
            self.present = True

    # --- the sample clock --------------------------------------------------------------------
    @property
    def sample_now(self) -> int:
        """The device sample the card's clock is at now."""
        with self._lock:
            return self._world_sample()

    def _world_sample(self) -> int:
        if math.isnan(self._world_start_s):
            self._world_start_s = self.clock()
        return math.floor((self.clock() - self._world_start_s) * self.device.sample_rate_hz)

    def _acquired(self) -> int:
        """Samples the inputs have taken since their trigger."""
        if math.isnan(self._start_s):
            return self._stopped_at
        return math.floor((self.clock() - self._start_s) * self.device.sample_rate_hz)

    def _running(self, kind: str) -> _Task | None:
        return next((t for t in self.tasks.values() if t.kind == kind and t.running), None)

    def _advance(self) -> None:
        """The outputs, as the clock has run: stopped (0 V) once it passed the last sample written."""
        ao = self._running("ao")
        if ao is None or math.isnan(self._start_s):
            return
        if self._acquired() > ao.position:
            self.underflows += 1
            self._unfed_until(self.clock())
            self._stop(ao, daq_error(DAQmxErrors.GEN_STOPPED_TO_PREVENT_REGEN_OF_OLD_SAMPLES, write=True), ao.position)

    def _unfed_until(self, now_s: float) -> None:
        """The host is back (a write, or the underflow its absence caused): how long it left the outputs."""
        self.longest_write_gap_s = max(self.longest_write_gap_s, now_s - self._last_write_s)
        self._last_write_s = now_s

    def _stop(self, task: _Task, error: DaqError | None = None, at_sample: int | None = None) -> None:
        """``task`` stops (at its card sample ``at_sample``, default now); outputs idle at 0 V."""
        if task.kind == "ao" and task.running:
            stop = self._acquired() if at_sample is None else at_sample
            self._ao_end = self._base + min(stop, task.position)
        if task.kind == "ai" and task.running:
            self._stopped_at = self._acquired()
            self._start_s = math.nan
        task.running, task.error = False, error or task.error

    # --- the outputs -------------------------------------------------------------------------
    def write(self, task: _Task, volts: np.ndarray) -> int:
        self._advance()
        if task.error is not None:
            raise task.error
        if task.running:
            self._unfed_until(self.clock())
        if task.running and not self.present:
            raise daq_error(DAQmxErrors.DEV_CANNOT_BE_ACCESSED, write=True)
        generated = min(self._acquired(), task.position) if task.running else 0
        if task.position + volts.shape[1] - generated > task.buffer_samples:
            raise daq_error(
                DAQmxErrors.SAMPLES_CAN_NOT_YET_BE_WRITTEN,
                "Write cannot be performed, because the number of samples to write is larger than the space "
                f"available in the buffer ({task.buffer_samples} samples).",
                write=True,
            )
        if math.isnan(self._start_s):  # generated from the trigger on
            self._pending = np.concatenate([self._pending, volts], axis=1)
        else:
            keep = max(0, self.device.sample_index - 1 - self._ao_first)  # the drive is read back from the rest
            self._ao = np.concatenate([self._ao[:, keep:], volts], axis=1)
            self._ao_first += keep
        task.position += volts.shape[1]
        return volts.shape[1]

    def _volts(self, start: int, end: int) -> np.ndarray:
        """Output volts of device samples [start, end): 0 where nothing is generated."""
        volts = np.zeros((len(self.outputs), end - start))
        stop = end if self._ao_end is None else min(end, self._ao_end)
        lo, hi = max(start, self._ao_first), min(stop, self._ao_first + self._ao.shape[1])
        if hi > lo:
            volts[:, lo - start : hi - start] = self._ao[:, lo - self._ao_first : hi - self._ao_first]
        return volts

    def _changes(self, start: int, end: int) -> list[tuple[int, tuple | None, float]]:
        """The coils' changes in device samples [start, end): (sample, amplitudes in A or None for off, Hz)."""
        changes: list[tuple[int, tuple | None, float]] = []
        i = start
        while i < end:
            if self._drive is None:
                nonzero = np.flatnonzero(np.any(self._volts(i + 1, end + 1) != 0.0, axis=0))
                if not nonzero.size:
                    return changes
                on = i + int(nonzero[0])  # sin(0) = 0 at the switch-on sample, not zero at the next
                changes.append(self._start_drive(on))
                i = on + 1
            else:
                on, amplitude_v, omega = self._drive
                k = np.arange(i, end)
                expected = np.outer(amplitude_v, np.sin(omega * (k - on)))
                actual = self._volts(i, end)
                off = np.flatnonzero(np.all(actual == 0.0, axis=0) & np.any(expected != 0.0, axis=0))
                stop = i + int(off[0]) if off.size else end
                if np.max(np.abs(actual[:, : stop - i] - expected[:, : stop - i]), initial=0.0) > DRIVE_TOLERANCE_V:
                    raise NotImplementedError("the simulated card drives the coils with sinusoids only")
                if not off.size:
                    return changes
                changes.append((stop, None, 0.0))
                self._drive = None
                i = stop
        return changes

    def _start_drive(self, on: int) -> tuple[int, tuple, float]:
        first, second = self._volts(on + 1, on + 2)[:, 0], self._volts(on + 2, on + 3)[:, 0]
        k = int(np.argmax(np.abs(first)))
        omega = math.acos(float(np.clip(second[k] / (2.0 * first[k]), -1.0, 1.0)))
        amplitude_v = first / math.sin(omega)
        self._drive = (on, amplitude_v, omega)
        frequency_hz = omega * self.device.sample_rate_hz / (2.0 * math.pi)
        return on, tuple(float(a) for a in amplitude_v / self.amplifier_v_per_a), frequency_hz

    # --- the inputs --------------------------------------------------------------------------
    def read(self, task: _Task, n: int, timeout_s: float) -> np.ndarray:
        """The task's next ``n`` samples, volts (channels, n), once the clock has taken them."""
        deadline = self.clock() + timeout_s
        while True:
            self._advance()
            if task.error is not None:
                raise task.error
            if not task.running:
                raise daq_error(
                    DAQmxErrors.CANNOT_READ_WHEN_AUTO_START_FALSE_AND_TASK_NOT_RUNNING_OR_COMMITTED, read=True
                )
            acquired = self._acquired()
            if acquired - task.position > task.buffer_samples:
                self.overruns += 1
                self._stop(task, daq_error(DAQmxErrors.SAMPLES_NO_LONGER_AVAILABLE, read=True))
                raise task.error  # type: ignore[misc]  # set just now
            if task.position + n <= acquired:
                break
            wait_s = (task.position + n - acquired) / self.device.sample_rate_hz
            if self.clock() + wait_s > deadline:
                raise daq_error(DAQmxErrors.SAMPLES_NOT_YET_AVAILABLE, f"Timeout: {timeout_s} s.", read=True)
            self._lock.release()  # the clock runs on while the host waits (a stop may come meanwhile)
            try:
                time.sleep(wait_s)
            finally:
                self._lock.acquire()
        start = self._base + task.position
        task.position += n
        return self._device_volts(start, n, task.channels)

    def _catch_up(self, sample: int) -> None:
        """The device runs on, coils off and nobody reading, to ``sample``."""
        self._coils(self._changes(self.device.sample_index, sample))
        if sample > self.device.sample_index:
            self.device.read(sample - self.device.sample_index)

    def _coils(self, changes) -> None:
        for index, amplitudes, frequency_hz in changes:
            if amplitudes is None:
                self.device.coils_off()
                self.offs.append(index)
            elif amplitudes:
                self.device.drive([amplitudes], [frequency_hz])
                self.drives.append((index, amplitudes, frequency_hz))

    def _device_volts(self, start: int, n: int, channels: list[tuple[str, float]]) -> np.ndarray:
        """Device samples [start, start + n) at the input ``channels`` ((terminal, range V)), volts."""
        if self.supply_current_a is not None:
            current_a = self.supply_current_a()
            if current_a != self.device.field_current_a:
                self.device.set_field_current(current_a)
        pieces = []
        for index, amplitudes, frequency_hz in self._changes(start, start + n) + [(start + n, (), 0.0)]:
            if index > self.device.sample_index:
                pieces.append(self.device.read(index - self.device.sample_index).samples)
            self._coils([(index, amplitudes, frequency_hz)])
        readings = np.concatenate([p.samples_t for p in pieces])
        saturated = np.concatenate([p.saturated for p in pieces])
        volts = np.zeros((len(channels), n))
        for row, (terminal, range_v) in enumerate(channels):
            if terminal in self.inputs:
                sensor = self.inputs.index(terminal)
                value = readings[:, sensor] * self.sensitivity_v_per_t
                value = np.where(saturated[:, sensor], np.where(value >= 0.0, math.inf, -math.inf), value)
                volts[row] = np.clip(value, -range_v, range_v)
        return volts

    # --- the tasks ---------------------------------------------------------------------------
    def create(self, name: str) -> int:
        if name and any(t.name == name for t in self.tasks.values()):
            raise daq_error(DAQmxErrors.DUPLICATE_TASK, f"Task name {name!r} is already used by an open task.")
        self._handles += 1
        task = _Task(name or f"_unnamedTask<{self._handles}>")
        self.tasks[self._handles] = task
        self.made.append(task)
        return self._handles

    def task(self, handle: int) -> _Task:
        if handle not in self.tasks:
            raise daq_error(DAQmxErrors.INVALID_TASK, f"Task handle {handle!r} is not an open task.")
        return self.tasks[handle]

    def add_channel(self, handle: int, kind: str, terminal: str, min_v: float, max_v: float) -> None:
        task = self.task(handle)
        if not self.present:
            raise daq_error(DAQmxErrors.DEV_CANNOT_BE_ACCESSED, f"Device: {self.device_name}")
        match = re.fullmatch(r"(\w+)/(ai|ao)(\d+)", str(terminal))
        if not match or match.group(1) != self.device_name:
            raise daq_error(
                DAQmxErrors.INVALID_DEVICE_ID,
                f"Device identifier is invalid. Device Specified: {str(terminal).split('/')[0]}",
            )
        if match.group(2) != kind:
            raise daq_error(
                DAQmxErrors.INVALID_PHYS_CHAN_TYPE, f"Physical channel {terminal!r} is not an {kind} channel."
            )
        if task.kind not in ("", kind):
            raise daq_error(DAQmxErrors.MULTI_CHAN_TYPES_IN_TASK, "Input and output channels cannot be in one task.")
        limit = AI_RANGE_V if kind == "ai" else AO_RANGE_V
        if not (-limit <= min_v < max_v <= limit):
            raise daq_error(
                DAQmxErrors.INVALID_ATTRIBUTE_VALUE, f"Requested range [{min_v}, {max_v}] V exceeds ±{limit} V."
            )
        task.kind = kind
        task.channels.append((terminal, max(-min_v, max_v)))

    def timing(self, handle: int, rate_hz: float, sample_mode: int, samps_per_chan: int) -> None:
        task = self.task(handle)
        if not task.channels:
            raise daq_error(DAQmxErrors.CAN_NOT_PERFORM_OP_WHEN_NO_CHANS_IN_TASK)
        if sample_mode != AcquisitionType.CONTINUOUS.value:
            raise daq_error(DAQmxErrors.INVALID_ATTRIBUTE_VALUE, "The bench streams: sample_mode must be CONTINUOUS.")
        if not 0.0 < rate_hz <= MAX_RATE_HZ:
            raise daq_error(DAQmxErrors.INVALID_ATTRIBUTE_VALUE, f"Sample clock rate {rate_hz} Hz is out of range.")
        # The card divides its timebase by an integer: another rate is coerced to the next one above.
        task.rate_hz, task.buffer_samples = (
            self.timebase_hz / math.floor(self.timebase_hz / rate_hz),
            int(samps_per_chan),
        )

    def start(self, handle: int) -> None:
        task = self.task(handle)
        self._advance()
        if not self.present:
            raise daq_error(DAQmxErrors.DEV_CANNOT_BE_ACCESSED, f"Device: {self.device_name}")
        if not task.rate_hz:
            raise daq_error(DAQmxErrors.INVALID_ATTRIBUTE_VALUE, "The task has no sample clock timing.")
        if task.kind == "ao":
            self._start_outputs(task)
        else:
            self._start_inputs(task)

    def _start_outputs(self, task: _Task) -> None:
        if task.trigger != f"/{self.device_name}/ai/StartTrigger":
            raise daq_error(
                DAQmxErrors.TRIG_LINE_NOT_FOUND_ROUTING,
                f"The outputs must start on the inputs' start trigger, not {task.trigger!r}.",
            )
        if task.regen_mode != RegenerationMode.DONT_ALLOW_REGENERATION.value:
            raise daq_error(DAQmxErrors.INVALID_ATTRIBUTE_VALUE, "A streamed output must not regenerate its buffer.")
        if task.idle_behavior != AOIdleOutputBehavior.ZERO_VOLTS.value:
            raise daq_error(DAQmxErrors.INVALID_ATTRIBUTE_VALUE, "The coils must go to zero when the outputs stop.")
        if not task.position:
            raise daq_error(DAQmxErrors.OUTPUT_BUFFER_EMPTY, "Generation cannot start: the output buffer is empty.")
        if self._running("ai") is not None:
            raise daq_error(
                DAQmxErrors.CAN_NOT_PERFORM_OP_WHILE_TASK_RUNNING,
                "The inputs' start trigger has passed: start the outputs first.",
            )
        task.running, task.error = True, None

    def _start_inputs(self, task: _Task) -> None:
        outputs = [t for t in self.tasks.values() if t.kind == "ao"]
        if not all(t.running and t.rate_hz == task.rate_hz for t in outputs):
            raise daq_error(
                DAQmxErrors.CAN_NOT_PERFORM_OP_WHILE_TASK_RUNNING,
                "The outputs must be armed on the inputs' trigger and rate before the inputs start.",
            )
        # The trigger: the card's sample 0 is the device's present sample; the outputs written
        # so far are generated from it.
        self._catch_up(self._world_sample())
        self._base = self.device.sample_index
        self._ao, self._ao_first, self._ao_end = self._pending, self._base, None
        self._pending = self._pending[:, :0]
        self._start_s = self._last_write_s = self.clock()
        task.position, task.running, task.error, self._stopped_at = 0, True, None, 0

    def stop(self, handle: int) -> None:
        task = self.task(handle)
        self._advance()
        self._stop(task)
        task.error = None
        if task.kind == "ao":  # a non-regenerating output starts again from an empty buffer
            task.position = 0
            self._pending = self._pending[:, :0]

    def clear(self, handle: int) -> None:
        if handle in self.tasks:
            self.stop(handle)
            del self.tasks[handle]
