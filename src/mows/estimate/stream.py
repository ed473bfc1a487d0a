"""The estimator's flow without its I/O: raw sample blocks and ring-down announcements in (as
the messages carry them), and per recorded ring-down its fit (:mod:`mows.estimate.ringdown`),
the field and gradient along the probe axis (:mod:`mows.estimate.axis`) and, while an f00
calibration runs (:mod:`mows.estimate.calibration.f00`), the OK fits offered to it.

With several probes listed (:mod:`mows.estimate.probe_set`) each window is fitted jointly
(:func:`mows.estimate.ringdown.fit_ringdowns`) over the probes it holds
(:func:`mows.estimate.probe_set.window_probes`: those its excitation lists, each at its own θ0,
or every listed probe) and gives one estimate per probe, each counted from that probe's f00.
A probe id the window lists but the set does not gets a failed fit naming it, never a number.
The f00 calibration is then refused (it is of one probe).

The estimator node feeds it its subscriptions and publishes what it returns. What the node's
parameters say (probe, fit options, settling, f00) comes with each ring-down as a
:class:`FitSettings`, read when the ring-down is complete, so a parameter change applies to
the next fit.
"""

import dataclasses
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
    fit_joint_segment,
    fit_segment,
    window_from_message,
)
from mows.physics.probe import Probe
from mows.records.stamps import NS_PER_S


@dataclasses.dataclass(frozen=True)
class JointSettings:
    """What the joint fit of several probes takes: the probes, the lines of those a window holds
    (each of them known to the set; ValueError when no model can be built) and the fit's options."""

    probes: tuple[ProbeEntry, ...]
    lines: Callable[[Sequence[WindowProbe]], list[ProbeLine]]
    options: FitOptions


@dataclasses.dataclass(frozen=True)
class FitSettings:
    """What fitting and inverting one ring-down take."""

    probe: Probe
    options: Callable[[float], FitOptions]  # θ0 → the fit's options; ValueError when no model can be built
    coil_off_skip_s: float
    f00_hz: float
    f00_std_hz: float
    joint: JointSettings | None = None  # several probes: their joint fit; None: one probe


@dataclasses.dataclass(frozen=True)
class Estimated:
    """One recorded ring-down of one probe: its window, fit and estimate along the axis;
    ``calibrated`` when its fit completed the running f00 calibration. ``probe_id`` is the
    probe's when several are listed (None: the single probe); ``unknown_probe`` when the window
    named a probe the set does not list."""

    window: RingdownWindow
    fit: RingdownFit
    estimate: AxisEstimate
    calibrated: bool = False
    probe_id: int | None = None
    unknown_probe: bool = False

    @property
    def stamp_ns(self) -> int:
        """Device time of the fit's first sample (the window's start and the fit's offset in it)."""
        return self.window.start_ns + round(self.fit.start_offset_s * NS_PER_S)

    def report(self) -> str:
        """The fit's report with its cycle, repeat and, with several probes, its probe."""
        probe = "" if self.probe_id is None else f" probe {self.probe_id}"
        return f"cycle {self.window.cycle_id} repeat {self.window.repeat_index}{probe}: {self.fit.report()}"


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
        RINGDOWN; a frequency-tuning one only with ``fit_tuning``). ValueError for an
        announcement that is no window."""
        if message.phase != message.PHASE_RINGDOWN or (message.tuning and not fit_tuning):
            return []
        return self.assembler.announce(window_from_message(message))

    def estimate_segments(self, segments: list[Segment], settings: FitSettings) -> list[Estimated]:
        """The estimates of every probe in each of ``segments`` (:meth:`estimate_all`), in order."""
        return [estimated for segment in segments for estimated in self.estimate_all(segment, settings)]

    def estimate_all(self, segment: Segment, settings: FitSettings) -> list[Estimated]:
        """The estimate of each probe in ``segment``: one, or one per probe it holds in id order."""
        if settings.joint is None:
            return [self.estimate(segment, settings)]
        joint, window = settings.joint, segment.window
        held = window_probes(joint.probes, window)
        known = [p for p in held if p.entry is not None]
        fits = {fit.probe_id: fit for fit in self._joint_fits(segment, settings, joint, known)}
        for p in held:
            if p.entry is None:
                fits[p.probe_id] = failure(
                    FitStatus.BAD_FIT, p.unknown_message(joint.probes), theta0_rad=p.theta0_rad, probe_id=p.probe_id
                )
        self.last = "; ".join(f"probe {k}: {fits[k].report()}" for k in sorted(fits))
        return [_estimated(window, fits[p.probe_id], p) for p in held]

    @staticmethod
    def _joint_fits(
        segment: Segment, settings: FitSettings, joint: JointSettings, known: list[WindowProbe]
    ) -> list[RingdownFit]:
        if not known:
            return []
        try:
            lines = joint.lines(known)
        except ValueError as error:
            return [
                failure(
                    FitStatus.BAD_FIT,
                    f"cannot build the signal model: {error}",
                    theta0_rad=p.theta0_rad,
                    probe_id=p.probe_id,
                )
                for p in known
            ]
        return fit_joint_segment(segment, lines, settings.coil_off_skip_s, joint.options)

    def estimate(self, segment: Segment, settings: FitSettings) -> Estimated:
        """Fit ``segment``, invert the fit, and offer an OK one to the running calibration."""
        window = segment.window
        try:
            options = settings.options(window.theta0_rad)
        except ValueError as error:  # e.g. a sensing axis of (0, 0): no model to fit
            fit = failure(FitStatus.BAD_FIT, f"cannot build the signal model: {error}", theta0_rad=window.theta0_rad)
        else:
            fit = fit_segment(segment, options, settings.coil_off_skip_s, settings.probe.damping_per_s)
        estimate = estimate_along_axis(fit, settings.probe, settings.f00_hz, settings.f00_std_hz)
        self.last = fit.report()
        calibrated = (
            estimate.ok
            and self.calibration is not None
            and self.calibration.offer(fit.frequency_hz, fit.frequency_std_hz) is not None
        )
        return Estimated(window, fit, estimate, calibrated)

    def begin_calibration(
        self, settings: FitSettings, reference_field_t: float, n_ringdowns: int, timeout_s: float
    ) -> F00Calibration:
        """A calibration of f00 of ``settings``' probe from the next OK ring-downs
        (:class:`F00Calibration`); ValueError, with the reason, for a request it cannot meet,
        while another one runs, or when several probes (``settings.joint``) share the windows."""
        probes = 1 if settings.joint is None else len(settings.joint.probes)
        if probes > 1:
            raise ValueError(
                f"the f00 calibration is of one probe and {probes} probes are listed: "
                "give each its f00 in the probes parameter, or calibrate each alone"
            )
        calibration = F00Calibration(settings.probe, reference_field_t, n_ringdowns, timeout_s)
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
