"""The paper's bench on an NI data-acquisition card, without the card: what the ``nidaqmx``
backend (:mod:`mows.device.backends.daqmx_backend`) computes, as plain functions over arrays.

The bench (Methods): two FL1-10 fluxgates on two analog inputs, hardware-timed at 20 kS/s; two
excitation coils on power amplifiers fed by two analog outputs, whose sample clock starts on the
analog inputs' start trigger, so that output sample i and input sample i are the same instant and
a coil switch-off is exact to the sample.

* :class:`DaqDevice`: the card's channels, ranges, the fluxgates' and amplifiers' gains, from the
  device YAML (docs/hardware.md; the paper's bench is ``hardware/ni_pcie6363.yaml``);
* :meth:`DaqDevice.field_t`: input volts → field along each sensor axis, T, with the samples at
  the input range's end flagged saturated (the fluxgates saturate during an excitation);
* :class:`CoilWaveforms`: the coil commands as output volts, sample by sample. Coil k carries
  I_k·sin(2πf·(i − i_on)/fs) from the command's sample i_on (so that the switch-off at a current
  peak that :func:`mows.physics.coils.excitation_samples` chooses is where the sequencer put
  it); the signed I_k are the setup's orientation-dependent amplitudes
  (:meth:`mows.physics.coils.CoilSetup.currents_a`, ∝ sin(θ0 + 135°) and sin(θ0 + 45°) on the
  largest-spacing setup); the amplifier turns V_k = I_k · ``amplifier_v_per_a`` into current.
"""

from __future__ import annotations

import bisect
import dataclasses
import math
import pathlib
from collections.abc import Callable
from typing import Any

import numpy as np

from mows.physics import ranges
from mows.physics.coils import CurrentCap
from mows.physics.schema import at, load_yaml, positive, refused, typed

HARDWARE_DIR = pathlib.Path(__file__).parent / "hardware"
PAPER_DEVICE_FILE = HARDWARE_DIR / "ni_pcie6363.yaml"
TERMINAL_CONFIGS = ("DEFAULT", "RSE", "NRSE", "DIFF", "PSEUDO_DIFF")
ADC_BITS = 16  # the PCIe-6363's converters: a sample at the range's last code is saturated


@dataclasses.dataclass(frozen=True)
class AnalogInput:
    """One fluxgate on one input: its ``physical_channel`` (``Dev1/ai0``), the terminal
    configuration, the input range ±``range_v`` and the fluxgate's output per tesla."""

    physical_channel: str
    sensitivity_v_per_t: float
    range_v: float = 10.0
    terminal_config: str = "DIFF"

    def __post_init__(self):
        positive("sensitivity_v_per_t", self.sensitivity_v_per_t)
        positive("range_v", self.range_v)
        if self.terminal_config not in TERMINAL_CONFIGS:
            raise refused("terminal_config", self.terminal_config, f"is not one of {TERMINAL_CONFIGS}")


@dataclasses.dataclass(frozen=True)
class AnalogOutput:
    """One coil's amplifier on one output: ``physical_channel`` (``Dev1/ao0``), range ±``range_v``."""

    physical_channel: str
    range_v: float = 10.0

    def __post_init__(self):
        positive("range_v", self.range_v)


# Each number of a device file and the quantity whose range it must lie in (mows.physics.ranges).
RANGED = {
    "sample_rate_hz": "sample_rate_hz",
    "block_s": "block_s",
    "output_lead_s": "output_lead_s",
    "read_timeout_s": "timeout_s",
    "watchdog_s": "watchdog_s",
    "current_cap_a": "coil_current_a",
}


@dataclasses.dataclass(frozen=True)
class DaqDevice:
    """The card and what is wired to it (YAML: :func:`load_daq_device`)."""

    inputs: tuple[AnalogInput, ...]
    outputs: tuple[AnalogOutput, ...]
    amplifier_v_per_a: float
    sample_rate_hz: float = 20_000.0
    block_s: float = 0.025  # the inputs are read in blocks of this
    # The outputs are written this far ahead of the newest input sample: a host stalled for less
    # (a tuning fit, a busy machine: stalls of 1.3 s at load 20-30 on two cores) never underflows
    # them. It is also the command lead: a coil command, a cancel too, applies this much later.
    output_lead_s: float = 2.0
    read_timeout_s: float = 1.0  # a read that waits longer than this is a fault of the card
    current_cap_a: float = 10.0  # the amplifiers' limit (Methods: up to 10 A)
    # A host that stops reading this long: coils and supply off. Longer than the lead, so that a
    # stall the lead survives is not cut short here.
    watchdog_s: float = 2.5
    # The threads that feed the card (the one that polls it, the supply's, the watchdog) under
    # SCHED_FIFO at this priority, 1-99, where the system allows it (0: the default policy):
    # busy processes beside the driver cannot then stall it beyond the lead.
    realtime_priority: int = 0
    name: str = "daq"

    def __post_init__(self):
        if len(self.inputs) != 2 or len(self.outputs) != 2:
            raise ValueError(
                f"{self.name}: the bench has 2 fluxgate inputs and 2 coil outputs, "
                f"got {len(self.inputs)} and {len(self.outputs)}"
            )
        for name in ("amplifier_v_per_a", "sample_rate_hz", "block_s", "output_lead_s", "read_timeout_s", "watchdog_s"):
            positive(name, getattr(self, name))
        for name, quantity in RANGED.items():
            ranges.check(quantity, getattr(self, name), f"{self.name}: {name}")
        CurrentCap(self.current_cap_a)
        if not 0 <= self.realtime_priority <= 99:
            raise refused("realtime_priority", self.realtime_priority, "must be 1-99 (SCHED_FIFO), or 0: off")
        if self.output_lead_s <= self.block_s:
            raise ValueError(
                f"{self.name}: output_lead_s = {self.output_lead_s} must exceed block_s = {self.block_s} "
                "(the outputs are written ahead of every input block)"
            )
        for output in self.outputs:
            if self.current_cap_a * self.amplifier_v_per_a > output.range_v:
                raise ValueError(
                    f"{self.name}: current_cap_a × amplifier_v_per_a = "
                    f"{self.current_cap_a * self.amplifier_v_per_a:g} V exceeds {output.physical_channel}'s "
                    f"range of ±{output.range_v:g} V"
                )
        _own_channels("inputs", [i.physical_channel for i in self.inputs], "fluxgate")
        _own_channels("outputs", [o.physical_channel for o in self.outputs], "coil's amplifier")
        if len({i.physical_channel.split("/")[0] for i in self.inputs}) != 1:
            raise ValueError(f"{self.name}: both inputs must be on one device (one task, one start trigger)")

    @property
    def device_name(self) -> str:
        """The card's name (``Dev1``), as the channels name it."""
        return self.inputs[0].physical_channel.split("/")[0]

    @property
    def start_trigger(self) -> str:
        """The inputs' start trigger, the terminal the outputs start on."""
        return f"/{self.device_name}/ai/StartTrigger"

    @property
    def block_samples(self) -> int:
        return max(1, round(self.block_s * self.sample_rate_hz))

    @property
    def lead_samples(self) -> int:
        return round(self.output_lead_s * self.sample_rate_hz)

    @property
    def stall_survived_s(self) -> float:
        """The longest host stall that loses nothing: the outputs' lead, unless the watchdog
        faults the card sooner."""
        return min(self.output_lead_s, self.watchdog_s)

    @property
    def range_t(self) -> float:
        """The field at the end of the smaller input range, T."""
        return min(i.range_v / i.sensitivity_v_per_t for i in self.inputs)

    @property
    def resolution_t(self) -> float:
        """One converter code, T (the coarser input)."""
        return max(_lsb_v(i.range_v) / i.sensitivity_v_per_t for i in self.inputs)

    def field_t(self, volts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Input volts (channels, n) as field (n, channels), T, and the saturation flags: a
        sample within half a code of the range's end is saturated (the converter cannot tell
        it from one beyond)."""
        volts = np.asarray(volts, dtype=float)
        sensitivity = np.array([i.sensitivity_v_per_t for i in self.inputs])[:, None]
        limit = np.array([i.range_v - 0.5 * _lsb_v(i.range_v) for i in self.inputs])[:, None]
        return (volts / sensitivity).T, (np.abs(volts) >= limit).T


def _own_channels(key: str, channels: list[str], what: str) -> None:
    """Refuse two channels wired to one terminal (NI's names ignore case): the second one's
    ``physical_channel`` names the first."""
    seen: dict[str, int] = {}
    for k, channel in enumerate(channels):
        first = seen.setdefault(channel.strip().lower(), k)
        if first != k:
            own = f"is {key}[{first}]'s too: each {what} needs a channel of its own"
            raise refused(f"{key}[{k}].physical_channel", channel, own)


def _lsb_v(range_v: float) -> float:
    return 2.0 * range_v / 2**ADC_BITS


def load_daq_device(path=PAPER_DEVICE_FILE) -> DaqDevice:
    """The device YAML at ``path`` (docs/hardware.md); ValueError naming the file, the key and the value."""
    return load_yaml(
        path,
        "device file",
        lambda data: typed(DaqDevice, data, inputs=_channels(AnalogInput), outputs=_channels(AnalogOutput)),
    )


def _channels(cls: type) -> Callable[[Any], tuple]:
    """A YAML list of channels as a tuple of ``cls``."""

    def channels(items: Any) -> tuple:
        if not isinstance(items, list):
            raise refused("", items, "must be a list of channels")
        built: list[Any] = []
        for k, item in enumerate(items):
            with at(k):
                built.append(typed(cls, item))
        return tuple(built)

    return channels


@dataclasses.dataclass(frozen=True)
class Drive:
    """Coil currents ``amplitudes_a`` at ``frequency_hz`` from sample ``on_index`` (zeros: off)."""

    on_index: int
    amplitudes_a: tuple
    frequency_hz: float


class CoilWaveforms:
    """The drives queued at their samples, synthesised as output volts in order.

    ``written`` is the first sample not yet synthesised: a drive for an earlier sample applies
    there (the card has those samples already), and :meth:`schedule` says where it applied.
    """

    def __init__(self, n_coils: int, sample_rate_hz: float, amplifier_v_per_a: float):
        self.sample_rate_hz = float(sample_rate_hz)
        self.amplifier_v_per_a = float(amplifier_v_per_a)
        self.written = 0
        self.driven_until = 0  # the sample after the last one synthesised with a coil driven
        self._off = Drive(0, (0.0,) * n_coils, 0.0)
        self._drives = [self._off]  # sorted by on_index; the first one is the present drive

    @property
    def coils_on(self) -> bool:
        """Whether the last synthesised sample drives a coil."""
        return any(self._drives[0].amplitudes_a)

    def schedule(self, at_index: int, amplitudes_a, frequency_hz: float) -> int:
        """Queue a drive from ``at_index`` (or the first unwritten sample); the sample it applies at."""
        applied = max(int(at_index), self.written)
        drive = Drive(applied, tuple(float(a) for a in amplitudes_a), float(frequency_hz))
        keys = [d.on_index for d in self._drives]
        self._drives.insert(bisect.bisect_right(keys, applied), drive)
        return applied

    def restart(self, index: int) -> None:
        """Every drive dropped, nothing written before sample ``index``: the coils off from there."""
        self.written = int(index)
        self.driven_until = 0
        self._drives = [dataclasses.replace(self._off, on_index=self.written)]

    def off_now(self) -> int:
        """Cancel every queued drive and switch off at the first unwritten sample."""
        self._drives = [self._drives[0]]
        return self.schedule(self.written, self._off.amplitudes_a, 0.0)

    def synthesise(self, end_index: int) -> np.ndarray:
        """Output volts (coils, n) for samples [written, end_index); ``written`` moves on."""
        start, end = self.written, max(int(end_index), self.written)
        volts = np.zeros((len(self._off.amplitudes_a), end - start))
        while self.written < end:
            drive = self._drives[0]
            nxt = self._drives[1].on_index if len(self._drives) > 1 else end
            stop = min(end, nxt)
            if any(drive.amplitudes_a) and stop > self.written:
                phase = 2.0 * math.pi * drive.frequency_hz / self.sample_rate_hz
                k = np.arange(self.written, stop) - drive.on_index
                currents = np.outer(drive.amplitudes_a, np.sin(phase * k))
                volts[:, self.written - start : stop - start] = currents * self.amplifier_v_per_a
                self.driven_until = stop
            self.written = stop
            if len(self._drives) > 1 and stop == nxt:
                self._drives.pop(0)
        return volts
