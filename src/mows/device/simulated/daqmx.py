"""The paper's bench simulated behind NI's ``nidaqmx`` Task API: a stand-in for the module, for
the tests and ``mows check-hardware --simulate`` on machines without NI's runtime or a card.

It holds the calls to what the real API requires of them, with NI's error codes: channels on
the card's terminals within its ranges; continuous hardware timing; the outputs started before
the inputs, on the inputs' start trigger, at their rate, with data written first and regeneration
off; writes within the output buffer and its range; reads into a (channels, n) float64 array,
within the input buffer, with a finite timeout; an output that runs out of data underflows and
stops the card. What the outputs write is what the amplifiers feed the coils: the stand-in reads
each drive back from the volts (the sinusoid's frequency from three samples, its amplitude from
one) and gives it to :class:`mows.sim.simulator.SimulatedDevice` at its exact sample; what the
inputs read is the simulator's fluxgates in volts, the supply's current (a callable, e.g. the
pyvisa-sim supply's) applied before each read. ``nidaqmx.constants`` are NI's own.
"""

from __future__ import annotations

import math
import re
import types
from collections.abc import Callable

import numpy as np

from mows.sim.simulator import SimulatedDevice

MAX_RATE_HZ = 2.0e6  # the PCIe-6363's aggregate input rate
AO_RANGE_V = 10.0
DRIVE_TOLERANCE_V = 1e-6  # a drive's samples follow its sinusoid to this, or the stand-in refuses


class DaqError(Exception):
    """As ``nidaqmx.errors.DaqError``: a message and NI's error code."""

    def __init__(self, message: str, error_code: int):
        super().__init__(f"{message}\nStatus Code: {error_code}")
        self.error_code = error_code


class DaqNotFoundError(Exception):
    """As ``nidaqmx.errors.DaqNotFoundError``."""


class SimulatedBench:
    """The simulated device wired to a card named ``device_name``: fluxgate k on ``inputs[k]``,
    coil k's amplifier on ``outputs[k]`` with ``amplifier_v_per_a``; the fluxgates give
    ``sensitivity_v_per_t``. ``supply_current_a``: the field supply's present current, read
    before each block (None: the scenario's stays)."""

    def __init__(
        self,
        device: SimulatedDevice,
        inputs=("Dev1/ai0", "Dev1/ai1"),
        outputs=("Dev1/ao0", "Dev1/ao1"),
        amplifier_v_per_a: float = 1.0,
        sensitivity_v_per_t: float = 1.0e6,
        supply_current_a: Callable[[], float] | None = None,
    ):
        self.device = device
        self.inputs, self.outputs = tuple(inputs), tuple(outputs)
        self.device_name = self.inputs[0].split("/")[0]
        self.amplifier_v_per_a = amplifier_v_per_a
        self.sensitivity_v_per_t = sensitivity_v_per_t
        self.supply_current_a = supply_current_a
        self.tasks: list[Task] = []
        self.drives: list[tuple[int, tuple, float]] = []  # (on sample, amplitudes A, Hz): what the coils got
        self.offs: list[int] = []  # the samples the coils went off at
        self._ao = np.zeros((len(self.outputs), 0))  # the output samples written and not yet generated
        self._ao_first = 0  # the sample index of self._ao's first column
        self._drive: tuple[int, np.ndarray, float] | None = None  # the present drive (on, volts amplitudes, ω)

    def module(self) -> types.SimpleNamespace:
        """The stand-in for ``import nidaqmx``."""
        import nidaqmx.constants  # NI's enumerations: pure Python, no runtime needed

        return types.SimpleNamespace(
            Task=lambda new_task_name="": Task(self, new_task_name),
            constants=nidaqmx.constants,
            errors=types.SimpleNamespace(DaqError=DaqError, DaqNotFoundError=DaqNotFoundError),
            stream_readers=types.SimpleNamespace(AnalogMultiChannelReader=AnalogMultiChannelReader),
            stream_writers=types.SimpleNamespace(AnalogMultiChannelWriter=AnalogMultiChannelWriter),
        )

    def turn_probe(self, theta0_rad: float) -> None:
        """The operator turns the stage (the coils must be off)."""
        self.device.set_orientations([theta0_rad])

    # --- the outputs -------------------------------------------------------------------------
    def write(self, volts: np.ndarray) -> None:
        # Only what the device has not generated is kept (the drive is read back from it).
        keep = max(0, self.device.sample_index - 1 - self._ao_first)
        self._ao = np.concatenate([self._ao[:, keep:], volts], axis=1)
        self._ao_first += keep

    @property
    def written(self) -> int:
        return self._ao_first + self._ao.shape[1]

    def _volts(self, start: int, end: int) -> np.ndarray:
        """Output samples [start, end) by sample index."""
        return self._ao[:, start - self._ao_first : end - self._ao_first]

    def _changes(self, start: int, end: int) -> list[tuple[int, tuple | None, float]]:
        """The coils' changes in samples [start, end): (sample, amplitudes in A or None for off, Hz)."""
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
                    raise NotImplementedError("the simulated bench drives the coils with sinusoids only")
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
    def read(self, n: int, channels: list[tuple[str, float]]) -> np.ndarray:
        """The next ``n`` samples of the input ``channels`` ((terminal, range V)), volts (channels, n)."""
        start = self.device.sample_index
        if self.written < start + n + 2:
            raise DaqError(
                "Onboard device memory underflow. Because of system and/or bus-bandwidth limitations, the driver "
                "could not write data to the device fast enough to keep up with the device output rate.",
                -200290,
            )
        if self.supply_current_a is not None:
            current_a = self.supply_current_a()
            if current_a != self.device.field_current_a:
                self.device.set_field_current(current_a)
        pieces = []
        for index, amplitudes, frequency_hz in self._changes(start, start + n) + [(start + n, (), 0.0)]:
            if index > self.device.sample_index:
                pieces.append(self.device.read(index - self.device.sample_index).samples)
            if amplitudes is None:
                self.device.coils_off()
                self.offs.append(index)
            elif amplitudes:
                self.device.set_coils(np.array(amplitudes), frequency_hz)
                self.drives.append((index, amplitudes, frequency_hz))
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


class _Collection:
    def __init__(self, task: Task, kind: str):
        self.task, self.kind = task, kind
        self.all = types.SimpleNamespace(ao_idle_output_behavior=None)

    def add_ai_voltage_chan(self, physical_channel, name_to_assign_to_channel="", terminal_config=None, **ranges):
        self.task.add_channel("ai", physical_channel, ranges.get("min_val", -5.0), ranges.get("max_val", 5.0))

    def add_ao_voltage_chan(self, physical_channel, name_to_assign_to_channel="", **ranges):
        self.task.add_channel("ao", physical_channel, ranges.get("min_val", -10.0), ranges.get("max_val", 10.0))


class Task:
    """A stand-in for ``nidaqmx.Task`` on the simulated bench."""

    def __init__(self, bench: SimulatedBench, name: str):
        self.bench, self.name = bench, name
        self.channels: list[tuple[str, float]] = []  # (terminal, range V)
        self.kind = ""
        self.ai_channels = _Collection(self, "ai")
        self.ao_channels = self.ai_channels
        self.rate_hz = 0.0
        self.buffer_samples = 0
        self.trigger = ""
        self.running = False
        self.closed = False
        self.timing = types.SimpleNamespace(cfg_samp_clk_timing=self._timing)
        self.triggers = types.SimpleNamespace(
            start_trigger=types.SimpleNamespace(cfg_dig_edge_start_trig=self._trigger)
        )
        self.in_stream = types.SimpleNamespace(task=self)
        self.out_stream = types.SimpleNamespace(task=self, regen_mode=None)
        bench.tasks.append(self)

    def add_channel(self, kind: str, terminal: str, min_v: float, max_v: float) -> None:
        match = re.fullmatch(r"(\w+)/(ai|ao)(\d+)", str(terminal))
        if not match or match.group(1) != self.bench.device_name or match.group(2) != kind:
            raise DaqError(
                f"Device identifier is invalid. Device specified: {str(terminal).split('/')[0]}, "
                f"physical channel {terminal!r}",
                -200220,
            )
        if self.kind not in ("", kind):
            raise DaqError("Input and output channels cannot be in one task", -200559)
        limit = 10.0 if kind == "ai" else AO_RANGE_V
        if not (-limit <= min_v < max_v <= limit):
            raise DaqError(f"Requested range [{min_v}, {max_v}] V exceeds the device's ±{limit} V", -200077)
        self.kind = kind
        self.channels.append((terminal, max(-min_v, max_v)))

    def _timing(self, rate, source="", active_edge=None, sample_mode=None, samps_per_chan=1000):
        import nidaqmx.constants as c

        if not self.channels:
            raise DaqError("Task contains no channels", -200478)
        if sample_mode != c.AcquisitionType.CONTINUOUS:
            raise DaqError("the bench streams: sample_mode must be AcquisitionType.CONTINUOUS", -200077)
        if not (0.0 < rate <= MAX_RATE_HZ):
            raise DaqError(f"Requested sample clock rate {rate} is outside the device's range", -200077)
        self.rate_hz, self.buffer_samples = float(rate), int(samps_per_chan)

    def _trigger(self, trigger_source, trigger_edge=None):
        self.trigger = trigger_source

    def start(self) -> None:
        import nidaqmx.constants as c

        if not self.rate_hz:
            raise DaqError("the task has no sample clock timing", -200077)
        if self.kind == "ao":
            if self.trigger != f"/{self.bench.device_name}/ai/StartTrigger":
                raise DaqError(f"the outputs must start on the inputs' start trigger, not {self.trigger!r}", -89125)
            if self.out_stream.regen_mode != c.RegenerationMode.DONT_ALLOW_REGENERATION:
                raise DaqError("a streamed output must not regenerate its buffer", -200077)
            if self.ai_channels.all.ao_idle_output_behavior != c.AOIdleOutputBehavior.ZERO_VOLTS:
                raise DaqError("the coils must go to zero when the outputs stop", -200077)
            if not self.bench.written:
                raise DaqError("Generation cannot be started because the output buffer is empty.", -200462)
            if any(t.running and t.kind == "ai" for t in self.bench.tasks):
                raise DaqError("the inputs' start trigger has passed: start the outputs first", -200479)
        else:
            outputs = [t for t in self.bench.tasks if t.kind == "ao" and not t.closed]
            if not all(t.running and t.rate_hz == self.rate_hz for t in outputs):
                raise DaqError(
                    "the outputs must be armed on the inputs' trigger and rate before the inputs start", -200479
                )
        self.running = True

    def stop(self) -> None:
        self.running = False

    def close(self) -> None:
        self.running, self.closed = False, True


class AnalogMultiChannelReader:
    """``nidaqmx.stream_readers.AnalogMultiChannelReader`` on the simulated bench."""

    def __init__(self, in_stream):
        self.task: Task = in_stream.task

    def read_many_sample(self, data, number_of_samples_per_channel=-1, timeout=10.0):
        task = self.task
        n = int(number_of_samples_per_channel)
        if not task.running:
            raise DaqError("The task is not running", -200473)
        if not (isinstance(timeout, (int, float)) and 0.0 < timeout < math.inf):
            raise DaqError(f"the bench's reads must time out: timeout = {timeout!r} s", -200474)
        if not (isinstance(data, np.ndarray) and data.dtype == np.float64 and data.flags.c_contiguous):
            raise DaqError("Read buffer must be a C-contiguous float64 numpy array", -200229)
        if data.shape != (len(task.channels), n) or not 0 < n <= task.buffer_samples:
            raise DaqError(
                f"Read buffer of shape {data.shape} for {n} samples of {len(task.channels)} channels", -200229
            )
        data[:] = task.bench.read(n, task.channels)
        return n


class AnalogMultiChannelWriter:
    """``nidaqmx.stream_writers.AnalogMultiChannelWriter`` on the simulated bench."""

    def __init__(self, out_stream, auto_start=False):
        self.task: Task = out_stream.task
        if auto_start:
            raise DaqError("a triggered output task is started explicitly, not by its first write", -200077)

    def write_many_sample(self, data, timeout=10.0):
        task, bench = self.task, self.task.bench
        if not (isinstance(data, np.ndarray) and data.dtype == np.float64 and data.flags.c_contiguous):
            raise DaqError("Write data must be a C-contiguous float64 numpy array", -200229)
        if data.ndim != 2 or data.shape[0] != len(task.channels):
            raise DaqError(f"Write data of shape {data.shape} for {len(task.channels)} channels", -200229)
        if np.any(np.abs(data) > np.array([r for _, r in task.channels])[:, None]):
            raise DaqError("Value passed to the Task/Channels is out of range", -200561)
        if bench.written + data.shape[1] - bench.device.sample_index > task.buffer_samples:
            raise DaqError(
                "Write cannot be performed, because the number of samples to write is larger than the space", -200292
            )
        bench.write(data)
        return data.shape[1]
