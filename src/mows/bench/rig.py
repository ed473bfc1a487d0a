"""The driver and the estimator on the simulated device, in device time and without ROS, for
one probe or for a scene's probes on one shared stage.

:class:`DeviceTimeRig` runs the driver's own cycles (:class:`mows.device.stream.device_time.DeviceTimeLoop`:
the driver's :class:`~mows.device.cycle.sequencer.CycleSequencer` with its duty-cycle limit and
current cap, on the simulated device with commands at exact samples), cuts the announced
ring-downs out of the stream as the estimator node does
(:class:`mows.estimate.segments.SegmentAssembler`) and fits each window's probes jointly with
their lever-aware pick-up (:func:`mows.estimate.segments.fit_segment`), each fit carrying its
probe id. Tuning
ring-downs retune the excitation and are not measurements.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mows.device.cycle.phases import CycleOutcome, CycleRequest, CycleSettings, Phase, PhaseEvent
from mows.device.cycle.tracking import TrackingLoop
from mows.device.stream.device_time import Block, DeviceTimeLoop, scheduled_device
from mows.estimate.probe_set import probe_lines
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, RingdownFit, fit_tuning
from mows.estimate.ringdown.start import white_noise_std
from mows.estimate.segments import RingdownWindow, Segment, SegmentAssembler, fit_segment
from mows.physics.coils import CurrentCap

BUFFER_S = 5.0  # the assembler keeps this much of the stream
#: One ring-down per group and cycle, the groups back to back: a map point of several probes per cycle.
ONE_ROUND = CycleSettings(repeats=1, gap_s=0.0, tuning_steps=0)  # one measured round, untuned


@dataclasses.dataclass(frozen=True)
class MeasuredRingdown:
    """A measurement ring-down (not a tuning one) of one probe: its window, its fit (with the
    probe's id) and which of its samples the device flagged saturated."""

    window: RingdownWindow
    fit: RingdownFit
    saturated: np.ndarray


@dataclasses.dataclass(frozen=True)
class MeasuredCycle:
    """One cycle to its end: the driver's outcome and its measurement ring-downs, in the order
    they were recorded."""

    outcome: CycleOutcome
    measured: tuple[MeasuredRingdown, ...]

    @property
    def fits(self) -> tuple[RingdownFit, ...]:
        """Every measurement fit, by probe id (in recorded order for each probe)."""
        return tuple(sorted((m.fit for m in self.measured), key=lambda fit: fit.probe_id))


class DeviceTimeRig:
    """``scenario``'s device (its probes on one shared stage when it has several) driven by
    cycles of ``settings`` with the coils capped at ``cap_a``."""

    def __init__(
        self,
        scenario,
        settings: CycleSettings,
        cap_a: float = 10.0,
        seed: int | None = None,
        coil_off_skip_s: float = COIL_OFF_SKIP_S,
    ):
        self.scenario = scenario
        rng = np.random.default_rng(scenario.seed if seed is None else seed)
        self.assembler = SegmentAssembler(BUFFER_S)
        self.coil_off_skip_s = coil_off_skip_s
        self.peak_current_a = 0.0
        self._measured: list[MeasuredRingdown] = []
        self.device = scheduled_device(scenario, CurrentCap(cap_a), rng)
        self.loop = DeviceTimeLoop(self.device, settings, fit=fit_tuning, on_block=self._block, on_event=self._event)
        self.sequencer, self.fs = self.loop.sequencer, self.loop.fs

    @property
    def time_s(self) -> float:
        """Device time so far."""
        return self.loop.time_s

    def first_block_noise_std_t(self) -> float:
        """White-noise σ per sample of the difference channel, measured on the first samples
        (the probe rests: they show the noise)."""
        quiet = self.loop.first_block.samples.samples_t
        return white_noise_std(quiet[:, 0] - quiet[:, 1])

    def set_settings(self, settings: CycleSettings) -> None:
        self.sequencer.settings = settings

    def run_cycle(self, request: CycleRequest) -> MeasuredCycle:
        """One cycle to its end, its measurement ring-downs fitted (the last one's segment
        completes with the block that reaches its end)."""
        self._measured = []
        outcome = self.loop.run_cycle(request)
        return MeasuredCycle(outcome, tuple(self._measured))

    def run_tracking(self, loop: TrackingLoop, ringdowns: int) -> list[MeasuredRingdown]:
        """Tracking cycles as the driver's session chains them (:mod:`mows.device.cycle.tracking`),
        over the rig's settings, until ``ringdowns`` are measured or the loop stops."""
        measured: list[MeasuredRingdown] = []
        while len(measured) < ringdowns and (request := loop.next_request(self.sequencer.settings)) is not None:
            cycle = self.run_cycle(request)
            measured += cycle.measured
            loop.on_outcome(cycle.outcome)
        return measured

    def coil_intervals(self) -> list[tuple[int, int]]:
        """[on, off) sample indices of every excitation, from the device's own coil record."""
        log = list(self.device.coil_log)
        ons = [index for index, on in log if on]
        offs = [index for index, on in log if not on]
        return [(a, b) for a, b in zip(ons, offs)]

    # --- what the loop hands on ----------------------------------------------------------------
    def _block(self, block: Block) -> None:
        if block.currents_a.size:
            self.peak_current_a = max(self.peak_current_a, float(np.max(np.abs(block.currents_a))))
        for segment in self.assembler.add_block(block.samples):
            self._fit(segment)

    def _event(self, event: PhaseEvent) -> None:
        if event.phase == Phase.RINGDOWN:
            window = RingdownWindow(
                event.stamp_ns,
                event.planned_duration_s,
                event.cycle_id,
                event.repeat_index,
                event.probe_theta0_rad[0],  # its first probe's own θ0 (each probe's is in its line)
                event.frequency_hz,
                event.tuning,
                event.probe_ids,
                event.probe_frequency_hz,
                event.probe_theta0_rad,
            )
            for segment in self.assembler.announce(window):
                self._fit(segment)

    def _fit(self, segment: Segment) -> None:
        """The window's probes fitted jointly, each at the tone it was driven with and where the
        stage holds it, the rest offset searched within their housing stops."""
        window = segment.window
        if window.tuning:
            return
        placed, members = self.device.device.placed, window.probe_ids
        lines = probe_lines(
            self.scenario.sensors.pair, [placed[k] for k in members], members, window.probe_frequency_hz
        )
        options = FitOptions(theta_stop_rad=min(placed[k].probe.theta_stop_rad for k in members))
        for fit in fit_segment(segment, lines, self.coil_off_skip_s, options):
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
