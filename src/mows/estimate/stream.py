"""The estimator's flow without its I/O: raw sample blocks and ring-down announcements in (as
the messages carry them), and per recorded ring-down its fit (:mod:`mows.estimate.ringdown`),
the field and gradient along the probe axis (:mod:`mows.estimate.axis`) and, while an f00
calibration runs (:mod:`mows.estimate.calibration.f00`), the OK fits offered to it.

The estimator tells apart the probes of its set (:mod:`mows.estimate.probe_set`; one, or
several sharing the fluxgates): each window is fitted jointly
(:func:`mows.estimate.ringdown.fit_ringdowns`) over the probes it holds
(:func:`mows.estimate.probe_set.window_probes`: those its excitation lists, each at its own θ0)
and gives one estimate per probe, each counted from that probe's f00. A probe id the window
lists but the set does not gets a failed fit naming it, never a number; its line, at the tone
the window announces for it, is fitted beside the others' so that no listed probe takes it
(:meth:`FitSettings.unlisted_lines`). The f00 calibration is of a set of one probe.

The estimator node feeds it its subscriptions and publishes what it returns. What the node's
parameters say (probes, fit options, settling) comes with each ring-down as a
:class:`FitSettings`, read when the ring-down is complete, so a parameter change applies to
the next fit.
"""

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

from mows.estimate.axis import AxisEstimate, estimate_along_axis
from mows.estimate.calibration.f00 import F00Calibration
from mows.estimate.probe_set import ProbeEntry, WindowProbe, window_probes
from mows.estimate.ringdown import FitOptions, FitStatus, ProbeLine, RingdownFit, failure
from mows.estimate.segments import (
    RingdownWindow,
    Segment,
    SegmentAssembler,
    block_from_message,
    fit_segment,
    window_from_message,
)
from mows.records.stamps import NS_PER_S, nanoseconds


@dataclasses.dataclass(frozen=True)
class FitSettings:
    """What fitting and inverting a ring-down window take: the probes told apart in it (one or
    more, in id order), the fit's lines of those a window holds (each known to the set;
    ValueError when no model can be built), the fit's options and the samples skipped after
    coil-off."""

    probes: tuple[ProbeEntry, ...]
    lines: Callable[[Sequence[WindowProbe]], list[ProbeLine]]
    options: FitOptions
    coil_off_skip_s: float

    def __post_init__(self) -> None:
        if not self.probes:
            raise ValueError("no probe to fit: the set of probes is empty")

    def window_fits(self, segment: Segment) -> list[tuple[WindowProbe, RingdownFit]]:
        """Each probe ``segment``'s window holds with its fit, in id order: a probe the set does
        not list, or one whose model cannot be built, gets a failed fit saying why."""
        held = window_probes(self.probes, segment.window)
        known = [p for p in held if p.entry is not None]
        fits = {p.probe_id: _bad_fit(p, p.unknown_message(self.probes)) for p in held if p.entry is None}
        try:
            lines = self.lines(known) if known else []
        except ValueError as error:
            fits |= {p.probe_id: _bad_fit(p, f"cannot build the signal model: {error}") for p in known}
        else:
            if lines:
                lines += self.unlisted_lines(held)
                fitted = fit_segment(segment, lines, self.coil_off_skip_s, self.options)
                fits |= {fit.probe_id: fit for fit in fitted if fit.probe_id not in fits}
        return [(p, fits[p.probe_id]) for p in held]

    def unlisted_lines(self, held: Sequence[WindowProbe]) -> list[ProbeLine]:
        """The lines of the probes ``held`` that the set does not list, each at the tone the
        window announced for it, in the paper's single term (their constants and places are
        not known). They are fitted, never reported: left out, a line of theirs would be taken
        by a listed probe's tone (the fit's start gives the lines it finds to the tones in order
        of frequency). None where θ0 is fitted, which is of one probe only."""
        if self.options.theta0_free:
            return []
        return [
            ProbeLine(p.probe_id, p.theta0_rad, p.tone_hz)
            for p in held
            if p.entry is None and math.isfinite(p.tone_hz) and p.tone_hz > 0
        ]


@dataclasses.dataclass(frozen=True)
class Estimated:
    """One recorded ring-down of one probe: its window, fit and estimate along the axis;
    ``calibrated`` when its fit completed the running f00 calibration; ``unknown_probe`` when
    the window named a probe the set does not list."""

    window: RingdownWindow
    fit: RingdownFit
    estimate: AxisEstimate
    calibrated: bool = False
    probe_id: int = 0
    unknown_probe: bool = False

    @property
    def stamp_ns(self) -> int:
        """Device time of the fit's first sample (the window's start and the fit's offset in it)."""
        return self.window.start_ns + round(self.fit.start_offset_s * NS_PER_S)

    def report(self) -> str:
        """The fit's report with its cycle, repeat and probe."""
        window = self.window
        return f"cycle {window.cycle_id} repeat {window.repeat_index} probe {self.probe_id}: {self.fit.report()}"


class RingdownEstimator:
    """Assembles ring-downs from the stream (keeping ``buffer_s`` of samples) and estimates each."""

    def __init__(self, buffer_s: float) -> None:
        self.assembler = SegmentAssembler(buffer_s)
        self.calibration: F00Calibration | None = None
        self.last = "no ring-down yet"  # the last fit's report

    def add_block(self, message: Any) -> list[Segment]:
        """A ``MagnetometerBlock``; the ring-downs it completes. ValueError for samples no device
        could have sent (nothing of them is kept)."""
        return self.assembler.add_block(block_from_message(message))

    def announce(self, message: Any, fit_tuning: bool = False) -> list[Segment]:
        """An ``ExcitationState``; the ring-downs complete by now once it announces one (phase
        RINGDOWN; a frequency-tuning one only with ``fit_tuning``), or once another phase begins
        inside one (its cycle ended: it is cut short there). ValueError for an announcement that
        is no window."""
        if message.phase != message.PHASE_RINGDOWN:
            return self.assembler.interrupt(nanoseconds(message.header.stamp), int(getattr(message, "device_epoch", 0)))
        if message.tuning and not fit_tuning:
            return []
        return self.assembler.announce(window_from_message(message))

    def estimate_segments(self, segments: list[Segment], settings: FitSettings) -> list[Estimated]:
        """The estimates of every probe in each of ``segments`` (:meth:`estimate`), in order."""
        return [estimated for segment in segments for estimated in self.estimate(segment, settings)]

    def estimate(self, segment: Segment, settings: FitSettings) -> list[Estimated]:
        """The estimate of each probe ``segment`` holds, in id order; an OK one is offered to the
        running calibration."""
        fits = settings.window_fits(segment)
        self.last = "; ".join(f"probe {p.probe_id}: {fit.report()}" for p, fit in fits)
        return [self._offered(_estimated(segment.window, fit, p)) for p, fit in fits]

    def _offered(self, estimated: Estimated) -> Estimated:
        """``estimated``, ``calibrated`` when it completed the running calibration."""
        if not (estimated.estimate.ok and self.calibration is not None):
            return estimated
        fit = estimated.fit
        done = self.calibration.offer(fit.frequency_hz, fit.frequency_std_hz) is not None
        return dataclasses.replace(estimated, calibrated=done)

    def begin_calibration(
        self, settings: FitSettings, reference_field_t: float, n_ringdowns: int, timeout_s: float
    ) -> F00Calibration:
        """A calibration of f00 of ``settings``' probe from the next OK ring-downs
        (:class:`F00Calibration`); ValueError, with the reason, for a request it cannot meet,
        while another one runs, or when several probes share the windows."""
        if len(settings.probes) > 1:
            raise ValueError(
                f"the f00 calibration is of one probe and {len(settings.probes)} probes are listed: "
                "give each its f00 in the probes parameter, or calibrate each alone"
            )
        calibration = F00Calibration(settings.probes[0].probe, reference_field_t, n_ringdowns, timeout_s)
        if self.calibration is not None:
            raise ValueError("a calibration is already running: try again after it")
        self.calibration = calibration
        return calibration

    def end_calibration(self) -> None:
        self.calibration = None


def _estimated(window: RingdownWindow, fit: RingdownFit, held: WindowProbe) -> Estimated:
    """One probe's fit of a joint window with its estimate along its own axis."""
    entry = held.entry
    if entry is None:
        estimate = AxisEstimate(fit.status, fit.message, fit.theta0_rad)
    else:
        estimate = estimate_along_axis(fit, entry.probe, entry.f00_hz, entry.f00_std_hz)
    return Estimated(window, fit, estimate, probe_id=held.probe_id, unknown_probe=entry is None)


def _bad_fit(held: WindowProbe, message: str) -> RingdownFit:
    return failure(FitStatus.BAD_FIT, message, theta0_rad=held.theta0_rad, probe_id=held.probe_id)
