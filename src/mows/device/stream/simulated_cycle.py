"""A measurement cycle of the driver's own sequencer on the simulated device, its ring-down
recorded with the truth to compare a fit with (:func:`simulate_cycle`, :class:`CycleRecord`),
and cycles as ``mows sim`` writes them (:func:`cycles_npz`).

The cycle is the driver's (:class:`mows.device.cycle.sequencer.CycleSequencer` in device time,
:class:`mows.device.stream.device_time.DeviceTimeLoop`): the stage turned to θ0 and left to
settle, the coils driven with the setup's current scheme at one frequency (no tuning excitation)
under the setup's cap and the duty-cycle limit, switched off at the drive current's peak nearest
the excitation time (:func:`mows.physics.coils.excitation_samples`), and the ring-down recorded.
A scene of several probes is rung by the multi-tone drive; the record keeps the first probe's
truth and the first group's excitation.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from mows.device.cycle.phases import CycleRequest, CycleSettings, Phase, PhaseEvent
from mows.device.simulated.scheduled import ScheduledDevice
from mows.device.stream.device_time import DeviceTimeLoop
from mows.physics.potential import ArcPotential
from mows.sim.readings import SimulatedBlock
from mows.sim.simulator import SimulatedDevice


@dataclasses.dataclass(frozen=True, eq=False)
class CycleRecord:
    """One excitation and its ring-down. ``block`` holds the samples (and the truth θ(t)); the
    ring-down starts at ``coil_off_index``; ``potential`` is U(θ) at the switch-off."""

    theta0_rad: float
    currents_a: np.ndarray
    frequency_hz: float
    block: SimulatedBlock
    coil_off_index: int
    potential: ArcPotential

    @property
    def sample_rate_hz(self) -> float:
        return self.block.samples.sample_rate_hz

    @property
    def samples_t(self) -> np.ndarray:
        return self.block.samples.samples_t

    @property
    def saturated(self) -> np.ndarray:
        return self.block.samples.saturated

    @property
    def theta_rad(self) -> np.ndarray:
        """The deflection of the probe (the first of a scene) at the samples (n,)."""
        return self.block.theta_rad[:, 0]

    def expected_frequency_hz(self, amplitude_rad=0.0):
        """Truth f(A) from the full potential (harmonic balance, Eq. S1)."""
        return self.potential.frequency_hz(amplitude_rad)

    def ringdown_amplitude_rad(self) -> float:
        """The first swing after switch-off: max |θ − θs| over the first period of the ring-down."""
        period = int(math.ceil(self.sample_rate_hz / self.frequency_hz))
        theta = self.theta_rad[self.coil_off_index : self.coil_off_index + period]
        return float(np.max(np.abs(theta - self.potential.rest_angle_rad())))

    def ringdown_frequency_hz(self, duration_s: float, points: int = 32) -> float:
        """Truth for a fit of the first ``duration_s`` of the ring-down: the time average of
        f(A(t)) with A(t) = A0·e^(−δt) from the first swing A0 (the frequency drifts as the
        amplitude decays, docs/physics.md §6.3, §6.5)."""
        t = (np.arange(points) + 0.5) / points * duration_s
        amplitudes = self.ringdown_amplitude_rad() * np.exp(-float(self.potential.damping_per_s) * t)
        return float(np.mean([self.potential.frequency_hz(a) for a in amplitudes]))


def simulate_cycle(
    device: SimulatedDevice,
    theta0_rad: float,
    amplitude_a: float,
    frequency_hz: float | None = None,
    excite_s: float = 0.5,
    ringdown_s: float = 0.5,
    settle_s: float = 0.0,
) -> CycleRecord:
    """One cycle of the driver's sequencer at θ0 on ``device`` (module docstring): ``settle_s`` at
    θ0, then one excitation of ``excite_s`` at base amplitude ``amplitude_a`` and ``ringdown_s`` of
    its ring-down. ``frequency_hz`` None: the expected small-amplitude frequency at θ0 (the truth,
    as after the paper's tuning), for which the stage is turned to θ0 first. ValueError when the
    cycle cannot start or run (a current above the setup's cap, say), with the sequencer's reason."""
    if frequency_hz is None:
        device.set_orientations(device.scenario.stage_orientations_rad(theta0_rad))
        frequency_hz = float(device.expected_frequencies_hz()[0])
    settings = CycleSettings(
        excitation_current_a=amplitude_a,
        excite_s=excite_s,
        ringdown_s=ringdown_s,
        repeats=1,
        tuning_steps=0,
        turn_settle_s=settle_s,
    )
    heard = _Heard(device)
    scheduled = ScheduledDevice(device, device.scenario.setup.cap)
    loop = DeviceTimeLoop(scheduled, settings, fit=_no_tuning, on_block=heard.blocks.append, on_event=heard.event)
    outcome = loop.run_cycle(CycleRequest(float(theta0_rad), frequency_hz=float(frequency_hz)))
    if not outcome.success:
        raise ValueError(f"the cycle at θ0 = {math.degrees(theta0_rad):.2f}° did not run: {outcome.message}")
    return heard.record(float(theta0_rad), round(ringdown_s * loop.fs))


class _Heard:
    """The blocks and the excitations of a running cycle, the potential at each switch-off."""

    def __init__(self, device: SimulatedDevice):
        self.device = device
        self.blocks: list[SimulatedBlock] = []
        self.excitations: list[tuple[PhaseEvent, PhaseEvent, ArcPotential]] = []
        self._exciting: PhaseEvent | None = None

    def event(self, event: PhaseEvent) -> None:
        if event.phase is Phase.EXCITING:
            self._exciting = event
        elif event.phase is Phase.RINGDOWN and self._exciting is not None:
            self.excitations.append((self._exciting, event, self.device.potentials()[0]))
            self._exciting = None

    def record(self, theta0_rad: float, ringdown_samples: int) -> CycleRecord:
        """The first excitation's record (a scene's first group of tones)."""
        exciting, ringdown, potential = self.excitations[0]
        block = self._samples(exciting.sample_index, ringdown.sample_index + ringdown_samples)
        off = ringdown.sample_index - exciting.sample_index
        currents = np.asarray(exciting.currents_a, float)
        return CycleRecord(theta0_rad, currents, exciting.frequency_hz, block, off, potential)

    def _samples(self, start: int, stop: int) -> SimulatedBlock:
        """Device samples [start, stop) from the blocks heard (the stretches nobody records, a gap
        or the settling, were never read into blocks)."""
        pieces = []
        for block in self.blocks:
            first = block.samples.first_sample_index
            lo, hi = max(start, first) - first, min(stop, first + len(block)) - first
            if lo < hi:
                pieces.append(_rows(block, lo, hi))
        return SimulatedBlock.concatenate(pieces)


def _rows(block: SimulatedBlock, start: int, stop: int) -> SimulatedBlock:
    """Rows [start, stop) of ``block``, with their truth."""
    return SimulatedBlock(
        block.samples.rows(start, stop),
        block.coils_on[start:stop],
        block.theta_rad[start:stop],
        block.theta_dot_rad_per_s[start:stop],
        block.currents_a[start:stop],
    )


def _no_tuning(*_args, **_kwargs):
    raise RuntimeError("a simulated cycle has no tuning excitation to fit")


def cycles_npz(records: list[CycleRecord], scenario_yaml: str) -> dict[str, Any]:
    """The arrays of ``mows sim --out`` (``numpy.savez``): per cycle its θ0, drive frequency, coil
    currents, first device sample, switch-off index, length, both fluxgates' samples and
    saturation flags, the probe's θ(t) and its expected small-amplitude frequency, with the
    sample rate and the scenario as YAML. Cycles differ in length (an excitation ends at a peak of
    its drive): the per-sample arrays are padded to the longest, NaN (not saturated) after each
    cycle's ``n_samples``."""
    return {
        "sample_rate_hz": records[0].sample_rate_hz,
        "theta0_rad": np.array([r.theta0_rad for r in records]),
        "frequency_hz": np.array([r.frequency_hz for r in records]),
        "currents_a": np.stack([r.currents_a for r in records]),
        "first_sample_index": np.array([r.block.samples.first_sample_index for r in records]),
        "coil_off_index": np.array([r.coil_off_index for r in records]),
        "n_samples": np.array([len(r.samples_t) for r in records]),
        "samples_t": _padded([r.samples_t for r in records], np.nan),
        "saturated": _padded([r.saturated for r in records], False),
        "theta_rad": _padded([r.theta_rad for r in records], np.nan),
        "expected_frequency_hz": np.array([float(r.expected_frequency_hz()) for r in records]),
        "scenario_yaml": scenario_yaml,
    }


def _padded(arrays, fill) -> np.ndarray:
    """The arrays stacked, each padded at the end with ``fill`` to the longest one's length."""
    longest = max(len(a) for a in arrays)
    out = np.full((len(arrays), longest, *arrays[0].shape[1:]), fill, dtype=arrays[0].dtype)
    for row, array in zip(out, arrays):
        row[: len(array)] = array
    return out
