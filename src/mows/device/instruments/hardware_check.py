"""Checking a bench step by step before measuring on it (``mows check-hardware``,
docs/hardware.md): the fluxgates at rest, each coil on its own at a safe current, the field
supply stepped and read back (with the field change at the fluxgates shown).

Each check reads the backend (:class:`mows.device.interface.Backend`) for a while and says what
it saw. Every wait has a deadline: a device that stops answering, a link that goes down (a card
fault, a supply that refuses a step) or a refused command ends the check with a PROBLEM line that
says why, and the checks after it are not run. What it concludes comes from the plain functions
below (:func:`lock_in_t`, the noise floor), so that a wiring fault (a coil on the wrong output, a
fluxgate on the wrong input, a supply that does not deliver) shows as a number next to the one
expected. A supply's read-back is judged only when it is stamped after the step it judges.
"""

from __future__ import annotations

import dataclasses
import math
import time

import numpy as np

from mows.device.instruments.scpi import ScpiSupplyConfig, load_supply_file
from mows.device.interface import CoilCommand, CoilTone, CommandResult, DeviceFault, FieldCurrentCommand, LinkEvent
from mows.records.samples import SampleBlock

VISIBLE = 10.0  # a coil or a supply step is seen when its signal is this many noise σ
ANSWER_S = 5.0  # a device answers a command, or delivers the samples due, within this (beyond their time)
READ_S = 0.05  # read in pieces of this while waiting for something other than samples


class CheckStopped(RuntimeError):
    """The device stopped the check: its link went down, it faulted, or it did not answer in time."""


@dataclasses.dataclass(frozen=True)
class CheckLine:
    """One check: what it is, whether it passed, and what it saw."""

    name: str
    ok: bool
    saw: str

    def __str__(self) -> str:
        return f"{'ok     ' if self.ok else 'PROBLEM'} {self.name}: {self.saw}"


def lock_in_t(samples_t: np.ndarray, frequency_hz: float, sample_rate_hz: float) -> np.ndarray:
    """Amplitude of each channel's component at ``frequency_hz`` (samples (n, channels)), T: the
    projection on sin and cos over whole periods, the mean removed."""
    n_periods = math.floor(len(samples_t) * frequency_hz / sample_rate_hz)
    n = round(n_periods * sample_rate_hz / frequency_hz)
    if n_periods < 1:
        raise ValueError(f"{len(samples_t)} samples hold no whole period of {frequency_hz} Hz")
    x = samples_t[:n] - samples_t[:n].mean(axis=0)
    phase = 2.0 * math.pi * frequency_hz * np.arange(n) / sample_rate_hz
    return 2.0 / n * np.hypot(np.sin(phase) @ x, np.cos(phase) @ x)


def lock_in_noise_t(noise_std_t: np.ndarray, n_samples: int) -> np.ndarray:
    """σ of :func:`lock_in_t` on white noise of ``noise_std_t`` per sample: 2σ/√n per quadrature."""
    return 2.0 * noise_std_t / math.sqrt(n_samples)


class HardwareCheck:
    """The checks on ``backend`` (a device that excites), with coils and supply at the given
    currents; the supply's read-back judged by its file's stated accuracy after its settling time
    (``supply_config``, the paper's NGM202 unless given)."""

    def __init__(
        self,
        backend,
        coil_current_a=0.02,
        frequency_hz=300.0,
        pulse_s=0.2,
        supply_step_a=0.1,
        supply_config: ScpiSupplyConfig | None = None,
        rest_s=1.0,
        names=(),
    ):
        self.backend = backend
        self.info = backend.info
        self.coil_current_a = coil_current_a
        self.frequency_hz = frequency_hz
        self.pulse_s = pulse_s
        self.supply_step_a = supply_step_a
        self.supply_config = supply_config or load_supply_file()
        self.rest_s = rest_s
        self.names = names or tuple(f"fluxgate {k + 1}" for k in range(self.info.n_channels))
        self._ids = 0
        self._next_index = 0

    def run(self, supply: bool = True) -> list[CheckLine]:
        """Every check in turn (the supply's when ``supply``), until one is stopped by the device."""
        lines: list[CheckLine] = []
        name = "fluxgates at rest"
        try:
            rest = self._read(self.rest_s)
            noise = rest.std(axis=0)
            lines.append(self._fluxgates(rest))
            for k in range(self.info.n_coils):
                name = self._coil_name(k)
                lines.append(self._coil(k, noise))
            if supply:
                name = "field supply"
                lines.append(self._supply(rest.mean(axis=0)))
        except CheckStopped as stopped:
            lines.append(CheckLine(name, False, f"stopped: {stopped}; the checks after it were not run"))
        return lines

    def _coil_name(self, k: int) -> str:
        return f"coil {k + 1} at {self.coil_current_a:g} A, {self.frequency_hz:g} Hz, {self.pulse_s:g} s"

    def _fluxgates(self, rest: np.ndarray) -> CheckLine:
        saturated = np.abs(rest) >= self.info.range_t
        parts = [
            f"{name} {1e6 * rest[:, k].mean():+.3f} µT ± {1e9 * rest[:, k].std():.3g} nT rms, "
            f"{int(saturated[:, k].sum())} of {len(rest)} saturated"
            + (" (flat: is it wired to its input?)" if rest[:, k].std() == 0.0 else "")
            for k, name in enumerate(self.names)
        ]
        ok = bool(not saturated.any() and np.all(rest.std(axis=0) > 0.0))
        return CheckLine("fluxgates at rest", ok, "; ".join(parts))

    def _coil(self, k: int, noise_t: np.ndarray) -> CheckLine:
        amplitudes = [0.0] * self.info.n_coils
        amplitudes[k] = self.coil_current_a
        on = self._command(CoilCommand(0, 0, (CoilTone(0, self.frequency_hz, tuple(amplitudes)),)))
        if not on.accepted:
            return CheckLine(self._coil_name(k), False, f"refused: {on.reason}")
        n = round(self.pulse_s * self.info.sample_rate_hz)
        off = self._command(CoilCommand(0, on.applied_sample_index + n))
        samples = self._read_span(on.applied_sample_index, off.applied_sample_index)
        seen = lock_in_t(samples, self.frequency_hz, self.info.sample_rate_hz)
        floor = lock_in_noise_t(noise_t, len(samples))
        clipped = np.sum(np.abs(samples) >= self.info.range_t, axis=0)
        self._read(0.5)  # the probe's ring-down fades before the next check
        saw = ", ".join(
            f"{name} {1e9 * s:.4g} nT (noise {1e9 * f:.2g} nT"
            + (f"; {c} samples saturated: clipped, lower the current" if c else "")
            + ")"
            for name, s, f, c in zip(self.names, seen, floor, clipped)
        )
        return CheckLine(
            self._coil_name(k),
            bool(np.any(seen > VISIBLE * floor)),
            saw,
        )

    def _supply(self, rest_mean_t: np.ndarray) -> CheckLine:
        result = self._command(FieldCurrentCommand(0, 0, self.supply_step_a))
        if not result.accepted:
            return CheckLine("field supply", False, f"refused: {result.reason}")
        readback = self._readback_after(result.applied_sample_index)
        stepped = self._read(0.5)  # settled: it was read back so
        back = self._command(FieldCurrentCommand(0, 0, 0.0))
        at_zero = self._readback_after(back.applied_sample_index)
        change = stepped.mean(axis=0) - rest_mean_t
        step_tolerance_a = self.supply_config.readback_tolerance_a(self.supply_step_a)
        zero_tolerance_a = self.supply_config.readback_tolerance_a(0.0)
        read_ok = abs(readback - self.supply_step_a) <= step_tolerance_a and abs(at_zero) <= zero_tolerance_a
        saw = (
            f"set {self.supply_step_a:.4f} A, read back {readback:.4f} A (± {1e3 * step_tolerance_a:.2g} mA); "
            "field change "
            + ", ".join(f"{name} {1e9 * c:+.4g} nT" for name, c in zip(self.names, change))
            + f"; set 0 A, read back {at_zero:.4f} A (± {1e3 * zero_tolerance_a:.2g} mA)"
        )
        # Judged by the read-back only: a pair whose field at the fluxgates is across their axes
        # (the Pasco pair along the sensor line) is not seen there; the change is for the operator.
        return CheckLine("field supply", bool(read_ok), saw)

    def _readback_a(self) -> float:
        """The supply's current as the device reports it (NaN when it reports none)."""
        stats = self.backend.stats()
        return float(stats.get("supply_readback_a", stats.get("supply_current_a", math.nan)))

    def _readback_after(self, step_index: int) -> float:
        """The supply's current read back after its step at sample ``step_index``: an older
        read-back (the step before, on a host catching up with the card) is not this step's.
        The backend reads back ``settle_s`` after it wrote the step, in the supply's own time."""
        self._read_span(self._next_index, step_index + 1)
        wait_s = self.supply_config.settle_s + ANSWER_S
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            if self.backend.stats().get("supply_readback_step", -1) >= step_index:
                return self._readback_a()
            self._read(READ_S)
        raise CheckStopped(f"the supply was not read back within {wait_s:g} s of its step")

    # --- the backend -------------------------------------------------------------------------
    def _command(self, command) -> CommandResult:
        self._ids += 1
        command = dataclasses.replace(
            command, command_id=self._ids, at_sample_index=max(command.at_sample_index, self._lead())
        )
        self.backend.send(command)
        deadline = time.monotonic() + ANSWER_S
        while time.monotonic() < deadline:
            for item in self.backend.poll(0.05):
                self._take(item)
                if isinstance(item, CommandResult) and item.command_id == self._ids:
                    return item
        raise CheckStopped(f"the device did not answer {command} within {ANSWER_S:g} s")

    def _lead(self) -> int:
        return self._next_index + self.backend.command_lead_samples

    def _take(self, item) -> np.ndarray | None:
        """A block's samples; CheckStopped when the link went down or the device faulted."""
        if isinstance(item, LinkEvent) and not item.up:
            raise CheckStopped(f"the link went down: {item.reason}")
        if isinstance(item, DeviceFault):
            raise CheckStopped(f"the device faulted: {item.reason}")
        if isinstance(item, SampleBlock):
            self._next_index = item.first_sample_index + len(item)
            return item.samples_t
        return None

    def _read(self, duration_s: float) -> np.ndarray:
        start = self._next_index
        return self._read_span(start, start + round(duration_s * self.info.sample_rate_hz))

    def _read_span(self, start: int, end: int) -> np.ndarray:
        """Samples [start, end) (those before the next one to arrive are gone)."""
        pieces: list[np.ndarray] = []
        first = end
        deadline = time.monotonic() + (end - self._next_index) / self.info.sample_rate_hz + ANSWER_S
        while self._next_index < end:
            if time.monotonic() > deadline:
                raise CheckStopped(f"the device delivered no samples for {ANSWER_S:g} s beyond their time")
            for item in self.backend.poll(0.05):
                samples = self._take(item)
                if samples is not None:
                    first = min(first, item.first_sample_index)
                    pieces.append(samples)
        if not pieces:
            return np.zeros((0, self.info.n_channels))
        stream = np.concatenate(pieces)
        return stream[max(0, start - first) : end - first]
