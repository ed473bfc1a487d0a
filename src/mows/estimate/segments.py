"""Cutting ring-downs out of the sample stream.

The driver streams fluxgate samples in blocks stamped by the device clock and announces each
ring-down by the device time at which the coils switched off and how long it lasts. This
module keeps the recent blocks and returns each announced window once every one of its
samples has arrived, or as soon as it is certain some never will (a sequence gap, a buffer
that has moved on). Missing samples are counted, never filled in: the fit refuses a segment
with a gap (``FitStatus.DATA_GAP``).

Device time and sample index are tied by t = t0 + (index − first_index)/fs within a block; the
announcement's time is converted to an index with the newest block's mapping, so the start
is exact to one sample as long as both come from the same clock. When the device's clock
restarts (a new ``epoch`` on the blocks: the driver reconfigured, the device rebooted) the
stream starts again: the samples buffered are of another clock, and a window announced on it
that has not completed never will (it is returned with every sample missing).

Announcements are kept by the driver for subscribers that join late, so the estimator hears
those made before it listened: a window that ended before the first block this buffer
received (or on an earlier clock) is not this estimator's to answer, and is only counted.
"""

from __future__ import annotations

import collections
import dataclasses
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from mows.estimate.ringdown import FitOptions, FitStatus, ProbeLine, RingdownFit, failure, fit_ringdowns
from mows.records import stamps
from mows.records.samples import SampleBlock


@dataclasses.dataclass(frozen=True)
class RingdownWindow:
    """An announced free ring-down: coils off at ``start_ns`` (device clock, integer ns) for
    ``duration_s``. The excitation lists the probes it rang (``probe_ids``: one, or several of
    a multi-tone drive), each with its tone and its own orientation in its own rotation plane,
    in the same order. An announcement recorded before excitations listed their probes lists
    none: one tone (``excitation_frequency_hz``) at one orientation (``theta0_rad``) rang
    whichever probes the estimator tells apart (:func:`mows.estimate.probe_set.window_probes`)."""

    start_ns: int
    duration_s: float
    cycle_id: int = 0
    repeat_index: int = 0
    theta0_rad: float = 0.0
    excitation_frequency_hz: float = math.nan
    tuning: bool = False  # a frequency-tuning ring-down, not a measurement
    probe_ids: tuple[int, ...] = ()
    probe_frequency_hz: tuple[float, ...] = ()
    probe_theta0_rad: tuple[float, ...] = ()
    device_epoch: int = 0  # the device clock start_ns is on (the blocks' epoch)

    def __post_init__(self) -> None:
        if not (
            isinstance(self.start_ns, (int, np.integer)) and math.isfinite(self.duration_s) and self.duration_s > 0
        ):
            raise ValueError(
                f"ring-down of cycle {self.cycle_id} announced at {self.start_ns!r} ns for "
                f"{self.duration_s!r} s: not a window"
            )
        listed = f"ring-down of cycle {self.cycle_id} lists probes {list(self.probe_ids)}"
        if not len(self.probe_ids) == len(self.probe_frequency_hz) == len(self.probe_theta0_rad):
            raise ValueError(
                f"{listed} with {len(self.probe_frequency_hz)} tones and {len(self.probe_theta0_rad)} "
                "orientations: not one each"
            )
        if len(set(self.probe_ids)) != len(self.probe_ids):
            raise ValueError(f"{listed}: an id twice")
        if not all(math.isfinite(a) for a in self.probe_theta0_rad):
            raise ValueError(f"{listed} at orientations {list(self.probe_theta0_rad)} rad: not all finite")


def block_from_message(message: Any) -> SampleBlock:
    """A ``mows_msgs/MagnetometerBlock`` (rclpy's or rosbags') as a :class:`Block`; ValueError
    when it does not describe one (channels of unequal length, no channels, a bad rate)."""
    if not message.channels:
        raise ValueError("a block without channels")
    samples = np.stack([np.asarray(c.field_t, np.float64) for c in message.channels], axis=1)
    saturated = np.stack([np.asarray(c.saturated, bool) for c in message.channels], axis=1)
    return SampleBlock(
        int(message.first_sample_index),
        stamps.nanoseconds(message.header.stamp),
        float(message.sample_rate_hz),
        samples,
        saturated,
        int(message.sequence),
        int(getattr(message, "device_epoch", 0)),
    )


def window_from_message(message: Any) -> RingdownWindow:
    """A ``mows_msgs/ExcitationState`` of phase RINGDOWN as a :class:`RingdownWindow` (one
    recorded before the message listed probes: none listed)."""
    return RingdownWindow(
        stamps.nanoseconds(message.header.stamp),
        float(message.planned_duration_s),
        int(message.cycle_id),
        int(message.repeat_index),
        float(message.theta0_rad),
        float(message.frequency_hz),
        bool(message.tuning),
        tuple(int(k) for k in getattr(message, "probe_ids", ())),
        tuple(float(f) for f in getattr(message, "probe_frequency_hz", ())),
        tuple(float(a) for a in getattr(message, "probe_theta0_rad", ())),
        int(getattr(message, "device_epoch", 0)),
    )


@dataclasses.dataclass(frozen=True)
class Segment:
    """The samples of one window (channels as columns), and how many of them never arrived;
    ``cut_short`` when its cycle ended inside it (the samples end there)."""

    window: RingdownWindow
    first_sample_index: int
    sample_rate_hz: float
    samples_t: np.ndarray
    saturated: np.ndarray
    missing_samples: int
    cut_short: bool = False


@dataclasses.dataclass
class _Pending:
    window: RingdownWindow
    start_index: int
    stop_index: int
    cut_short: bool = False


class SegmentAssembler:
    """Buffers about ``buffer_s`` of blocks and assembles announced ring-down windows.

    Counters (for diagnostics): ``blocks``, ``gaps`` (blocks that did not follow on from the one
    before: lost blocks, one gap per run of them), ``missing_samples`` (the samples in those gaps),
    ``rate_changes`` (a new sample rate or number of channels restarts the buffer), ``late_windows``
    (announced after their samples left the buffer), ``device_restarts`` (blocks of a new device
    clock: the stream starts again), ``windows_before_start`` (ring-downs over before the first
    block arrived: announced to a late listener, not recorded by it).
    """

    def __init__(self, buffer_s: float = 5.0) -> None:
        if not (math.isfinite(buffer_s) and buffer_s > 0):
            raise ValueError(f"buffer_s = {buffer_s!r} must be a positive number of seconds")
        self.buffer_s = buffer_s
        self._blocks: collections.deque[SampleBlock] = collections.deque()
        self._pending: list[_Pending] = []
        self.blocks = 0
        self.gaps = 0
        self.missing_samples = 0
        self.rate_changes = 0
        self.late_windows = 0
        self.device_restarts = 0
        self.windows_before_start = 0
        self._start: SampleBlock | None = None  # the first block received: where listening began

    # --- input --------------------------------------------------------------------------
    def add_block(self, block: SampleBlock) -> list[Segment]:
        """Take a block; return the segments it completes (and, on a new device clock, those
        that never will)."""
        newest = self._blocks[-1] if self._blocks else None
        lost: list[Segment] = []
        if newest is not None and block.epoch != newest.epoch:
            self.device_restarts += 1
            lost = self._of_another_clock(block.epoch)
            self._blocks.clear()
            newest = None
        if newest is not None and (
            block.sample_rate_hz != newest.sample_rate_hz or block.samples_t.shape[1] != newest.samples_t.shape[1]
        ):
            self.rate_changes += 1
            self._blocks.clear()
        elif newest is not None and block.first_sample_index > newest.end_index:
            self.gaps += 1
            self.missing_samples += block.first_sample_index - newest.end_index
        elif newest is not None and block.first_sample_index < newest.end_index:
            return []  # a repeat or an out-of-order block: the samples are already here or gone
        self._blocks.append(block)
        self.blocks += 1
        if self._start is None:
            self._start = block
            self._pending = [p for p in self._pending if not self._before_start(p.window, block)]
        self._prune()
        return lost + self._complete()

    def announce(self, window: RingdownWindow) -> list[Segment]:
        """Register a ring-down; return it at once if its samples are all here already, or if
        they are of a device clock that has restarted since."""
        if self._start is not None and self._before_start(window, self._start):
            return []
        newest = self._blocks[-1] if self._blocks else None
        if newest is not None and window.device_epoch < newest.epoch:
            return [self._unrecorded(window)]
        same_clock = newest is not None and window.device_epoch == newest.epoch
        self._pending.append(_Pending(window, *self._index_range(window, newest if same_clock else None)))
        return self._complete() if newest is not None else []

    def interrupt(self, stamp_ns: int, device_epoch: int) -> list[Segment]:
        """A phase announced at ``stamp_ns`` on the clock ``device_epoch``: a ring-down it
        begins inside was cut short (its cycle was cancelled or aborted; a cycle's next phase
        begins where its ring-down ends). Such a window ends there; the windows complete by now."""
        newest = self._blocks[-1] if self._blocks else None
        if newest is None or newest.epoch != device_epoch:
            return []
        at = newest.index_at(stamp_ns)
        for pending in self._pending:
            # one sample's slack: the announcement's stamp and the window's are rounded apart
            if pending.window.device_epoch == device_epoch and pending.start_index < at < pending.stop_index - 1:
                pending.stop_index, pending.cut_short = max(at, pending.start_index + 1), True
        return self._complete()

    def _before_start(self, window: RingdownWindow, start: SampleBlock) -> bool:
        """Whether ``window`` was over before ``start``, the first block (counted when it was)."""
        before = window.device_epoch < start.epoch or (
            window.device_epoch == start.epoch and self._index_range(window, start)[1] <= start.first_sample_index
        )
        self.windows_before_start += before
        return before

    def _of_another_clock(self, epoch: int) -> list[Segment]:
        """The windows that blocks of ``epoch`` can no longer complete: those of earlier clocks."""
        lost = [p.window for p in self._pending if p.window.device_epoch < epoch]
        self._pending = [p for p in self._pending if p.window.device_epoch >= epoch]
        return [self._unrecorded(window) for window in lost]

    @staticmethod
    def _unrecorded(window: RingdownWindow) -> Segment:
        """A window none of whose samples will arrive: the device's clock restarted."""
        return Segment(window, -1, 1.0, np.full((1, 1), np.nan), np.zeros((1, 1), bool), 1)

    # --- assembly -----------------------------------------------------------------------
    @staticmethod
    def _index_range(window: RingdownWindow, reference: SampleBlock | None) -> tuple[int, int]:
        if reference is None:
            return -1, -1  # resolved when the first block arrives
        start = reference.index_at(window.start_ns)
        return start, start + max(1, round(window.duration_s * reference.sample_rate_hz))

    def _complete(self) -> list[Segment]:
        newest = self._blocks[-1]
        done, waiting = [], []
        for pending in self._pending:
            if pending.window.device_epoch != newest.epoch:  # a later clock's: its blocks are to come
                waiting.append(pending)
                continue
            if pending.start_index < 0:
                pending.start_index, pending.stop_index = self._index_range(pending.window, newest)
            if pending.stop_index <= newest.end_index:
                done.append(self._cut(pending))
            else:
                waiting.append(pending)
        self._pending = waiting
        return done

    def _cut(self, pending: _Pending) -> Segment:
        """The window's samples from the buffer, NaN (and counted) where none arrived."""
        first = self._blocks[0]
        n = pending.stop_index - pending.start_index
        channels = first.samples_t.shape[1]
        samples = np.full((n, channels), np.nan)
        saturated = np.zeros((n, channels), bool)
        filled = np.zeros(n, bool)
        for block in self._blocks:
            lo = max(block.first_sample_index, pending.start_index)
            hi = min(block.end_index, pending.stop_index)
            if lo < hi:
                samples[lo - pending.start_index : hi - pending.start_index] = block.samples_t[
                    lo - block.first_sample_index : hi - block.first_sample_index
                ]
                saturated[lo - pending.start_index : hi - pending.start_index] = block.saturated[
                    lo - block.first_sample_index : hi - block.first_sample_index
                ]
                filled[lo - pending.start_index : hi - pending.start_index] = True
        if pending.start_index < first.first_sample_index:
            self.late_windows += 1
        return Segment(
            pending.window,
            pending.start_index,
            first.sample_rate_hz,
            samples,
            saturated,
            int(np.count_nonzero(~filled)),
            pending.cut_short,
        )

    def _prune(self) -> None:
        """Memory stays bounded: a window older than the buffer completes with missing samples."""
        newest = self._blocks[-1]
        keep_from = newest.end_index - round(self.buffer_s * newest.sample_rate_hz)
        while len(self._blocks) > 1 and self._blocks[0].end_index <= keep_from:
            self._blocks.popleft()


def gap_message(segment: Segment) -> str:
    """Why a segment with missing samples is not fitted."""
    return (
        f"{segment.missing_samples} of {len(segment.samples_t)} samples of the ring-down never "
        "arrived (a sequence gap, a late announcement or the device clock restarted); not fitted across a gap"
    )


def fit_segment(
    segment: Segment,
    lines: Sequence[ProbeLine],
    coil_off_skip_s: float = 0.0,
    options: FitOptions = FitOptions(),
) -> list[RingdownFit]:
    """The fit of one assembled window in which the probes of ``lines`` ring down, one or several
    together (a multi-tone excitation's, :mod:`mows.physics.multitone`): one
    :class:`RingdownFit` per line, in order (:func:`mows.estimate.ringdown.fit_ringdowns`). A
    window with missing samples is refused for every probe (``FitStatus.DATA_GAP``), never patched;
    one cut short by its cycle's end is not a measurement (``FitStatus.TOO_SHORT``): the driver
    does not count it as recorded."""
    if segment.cut_short:
        message = (
            f"the ring-down was cut short after {len(segment.samples_t) / segment.sample_rate_hz:.2f} s of "
            f"{segment.window.duration_s:.2f} s: its cycle ended (cancelled or aborted); not a measurement"
        )
        return [
            failure(FitStatus.TOO_SHORT, message, theta0_rad=line.theta0_rad, probe_id=line.probe_id) for line in lines
        ]
    if segment.missing_samples:
        message = gap_message(segment)
        return [
            failure(FitStatus.DATA_GAP, message, theta0_rad=line.theta0_rad, probe_id=line.probe_id) for line in lines
        ]
    return fit_ringdowns(segment.samples_t, segment.sample_rate_hz, lines, segment.saturated, options, coil_off_skip_s)
