"""The driver and the estimator on the simulated device, in device time and without ROS.

:class:`DeviceTimeRig` runs the driver's own cycle state machine
(:class:`mows.device.cycle.sequencer.CycleSequencer`, with its duty-cycle limit and current cap) on the
simulated device with commands at exact samples (:class:`mows.device.simulated.scheduled.ScheduledDevice`),
cuts the announced ring-downs out of the stream as the estimator node does
(:class:`mows.estimate.segments.SegmentAssembler`) and fits them with the lever-aware pick-up
(:func:`mows.estimate.segments.fit_segment`). The device's clock is the only clock: a run takes
as long as the simulator needs, not as long as the device would. Stretches nobody records (a gap,
the probe settling) are integrated without reading the sensors.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mows.device.cycle.phases import CycleOutcome, CycleRequest, CycleSettings, CycleStep, Phase, PhaseEvent
from mows.device.cycle.sequencer import CycleSequencer
from mows.device.cycle.tracking import TrackingLoop
from mows.device.interface import CoilCommand, CommandResult
from mows.device.simulated.scheduled import OverCap, ScheduledDevice
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, RingdownFit, fit_ringdown
from mows.estimate.ringdown.start import white_noise_std
from mows.estimate.segments import RingdownWindow, SegmentAssembler, fit_segment
from mows.physics.coils import CurrentCap
from mows.sim.simulator import SimulatedDevice

CHUNK_S = 0.025  # samples are read in pieces of this, as the sim backend does
BUFFER_S = 5.0  # the assembler keeps this much of the stream


@dataclasses.dataclass(frozen=True)
class MeasuredRingdown:
    """A measurement ring-down (not a tuning one): its window, its fit and which of its samples
    the device flagged saturated."""

    window: RingdownWindow
    fit: RingdownFit
    saturated: np.ndarray


class DeviceTimeRig:
    """``scenario``'s device driven by cycles of ``settings`` with the coils capped at ``cap_a``."""

    def __init__(
        self,
        scenario,
        settings: CycleSettings,
        cap_a: float = 10.0,
        seed: int | None = None,
        coil_off_skip_s: float = COIL_OFF_SKIP_S,
    ):
        self.scenario = scenario
        self.probe = scenario.probe
        rng = np.random.default_rng(scenario.seed if seed is None else seed)
        self.device = ScheduledDevice(SimulatedDevice(scenario, rng), CurrentCap(cap_a))
        self.fs = self.device.device.sample_rate_hz
        self.sequencer = CycleSequencer(
            settings, scenario.setup, self.device.cap, self.fs, self.probe.f00_hz, fit=fit_ringdown
        )
        self.assembler = SegmentAssembler(BUFFER_S)
        self.coil_off_skip_s = coil_off_skip_s
        self.peak_current_a = 0.0
        self._chunk = max(1, round(CHUNK_S * self.fs))
        self._results: list[CommandResult] = []
        self._options: dict[float, FitOptions] = {}
        self._measured: list[MeasuredRingdown] = []
        self._outcome: CycleOutcome | None = None
        self._idle_until = 0
        # The sequencer anchors its clock on the first samples; the probe rests, so they show the noise.
        self._quiet = self._read(self._chunk)[0].samples.samples_t

    @property
    def time_s(self) -> float:
        """Device time so far."""
        return self.device.next_index / self.fs

    def first_block_noise_std_t(self) -> float:
        """White-noise σ per sample of the difference channel, measured on the first samples."""
        return white_noise_std(self._quiet[:, 0] - self._quiet[:, 1])

    def set_settings(self, settings: CycleSettings) -> None:
        self.sequencer.settings = settings

    def run_cycle(self, request: CycleRequest) -> tuple[bool, str, list[MeasuredRingdown]]:
        """One cycle to its end: (success, message, its measurement ring-downs and their fits)."""
        self._outcome, self._measured = None, []
        self._act(self.sequencer.start(request))
        while self._outcome is None:
            if self._idle_until > self.device.next_index:
                self.device.idle_until(self._idle_until)
                self._idle_until = 0
            self._read(self._chunk)
        # The last ring-down's segment completes with the block that reaches its end.
        return self._outcome.success, self._outcome.message, self._measured

    def run_tracking(self, loop: TrackingLoop, ringdowns: int) -> list[MeasuredRingdown]:
        """Tracking cycles as the driver's session chains them (:mod:`mows.device.cycle.tracking`),
        over the rig's settings, until ``ringdowns`` are measured or the loop stops."""
        measured: list[MeasuredRingdown] = []
        while len(measured) < ringdowns and (request := loop.next_request(self.sequencer.settings)) is not None:
            measured += self.run_cycle(request)[2]
            assert self._outcome is not None  # run_cycle returns once its cycle has ended
            loop.on_outcome(self._outcome)
        return measured

    def coil_intervals(self) -> list[tuple[int, int]]:
        """[on, off) sample indices of every excitation, from the device's own coil record."""
        log = list(self.device.coil_log)
        ons = [index for index, on in log if on]
        offs = [index for index, on in log if not on]
        return [(a, b) for a, b in zip(ons, offs)]

    # --- the loop ----------------------------------------------------------------------------
    def _read(self, n: int) -> list:
        blocks = self.device.read_until(self.device.next_index + n)
        for block in blocks:
            if block.currents_a.size:
                self.peak_current_a = max(self.peak_current_a, float(np.max(np.abs(block.currents_a))))
            for segment in self.assembler.add_block(block.samples):
                self._fit(segment)
            self._act(self.sequencer.on_samples(block.samples))
        return blocks

    def _act(self, step: CycleStep) -> None:
        steps = [step]
        while steps:
            step = steps.pop(0)
            if step.coils_off_now:
                self.device.switch_off_at(self.device.next_index)
            for command in step.commands:
                self._send(command)
            for event in step.events:
                self._event(event)
            if step.outcome is not None:
                self._outcome = step.outcome
            results, self._results = self._results, []
            steps += [self.sequencer.on_result(result) for result in results]

    def _send(self, command) -> None:
        try:
            if isinstance(command, CoilCommand):
                applied = self.device.schedule_coils(
                    command.at_sample_index, command.amplitudes_a, command.frequency_hz
                )
            else:
                applied = self.device.schedule_orientation(command.at_sample_index, command.theta0_rad)
            self._results.append(CommandResult(command.command_id, True, applied))
        except (OverCap, RuntimeError, ValueError) as refused:
            self._results.append(CommandResult(command.command_id, False, reason=str(refused)))

    def _event(self, event: PhaseEvent) -> None:
        if event.phase in (Phase.GAP, Phase.SETTLING) and event.planned_duration_s > 0:
            # Nobody records these samples: the probe moves on without its sensors being read.
            self._idle_until = event.sample_index + round(event.planned_duration_s * self.fs)
        if event.phase == Phase.RINGDOWN:
            window = RingdownWindow(
                event.stamp_ns,
                event.planned_duration_s,
                event.cycle_id,
                event.repeat_index,
                event.theta0_rad,
                event.frequency_hz,
                event.tuning,
            )
            for segment in self.assembler.announce(window):
                self._fit(segment)

    def _fit(self, segment) -> None:
        window = segment.window
        if window.tuning:
            return
        key = round(window.theta0_rad, 12)
        if key not in self._options:
            self._options[key] = FitOptions.lever_aware(self.scenario.sensors.pair, self.probe, window.theta0_rad)
        fit = fit_segment(segment, self._options[key], self.coil_off_skip_s, self.probe.damping_per_s)
        self._measured.append(MeasuredRingdown(window, fit, segment.saturated))


def max_duty_fraction(intervals, window_samples: int) -> float:
    """The largest share of coil-on samples in any window of ``window_samples`` (the worst
    window ends at the end of an excitation, :mod:`mows.device.cycle.duty`)."""
    worst = 0.0
    for _, off in intervals:
        start = off - window_samples
        on = sum(max(0, min(b, off) - max(a, start)) for a, b in intervals)
        worst = max(worst, on / window_samples)
    return worst
