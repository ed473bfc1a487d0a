"""The device's sample clock: sample i is taken at epoch + i / sample_rate_hz.

A simulated device runs on this clock in real time: the samples it may have taken are those
whose time has come on the host's monotonic clock since it started. Counting samples from
one start instant, instead of adding up sleeps, keeps the long-run sample rate exact however
late each wake-up is. Stamps are integer nanoseconds (20 kS/s is exactly 50 000 ns a sample).
"""

import math
import time
from collections.abc import Callable


class DeviceClock:
    """``epoch_ns``: the device time of sample 0, ns (the host's wall clock at start-up by
    default, so that stamps read as dates); ``monotonic``: the host clock that paces it, s."""

    def __init__(
        self, sample_rate_hz: float, epoch_ns: int | None = None, monotonic: Callable[[], float] = time.monotonic
    ):
        if not (math.isfinite(sample_rate_hz) and sample_rate_hz > 0.0):
            raise ValueError(f"sample_rate_hz = {sample_rate_hz!r} must be a positive rate")
        self.sample_rate_hz = float(sample_rate_hz)
        self.epoch_ns = time.time_ns() if epoch_ns is None else int(epoch_ns)
        self._monotonic = monotonic
        self._start_s = monotonic()

    def stamp_ns(self, sample_index: int) -> int:
        """Device time of sample ``sample_index``, ns."""
        return self.epoch_ns + round(sample_index * 1e9 / self.sample_rate_hz)

    def due_index(self) -> int:
        """The number of samples whose time has come (samples 0 … due − 1)."""
        return math.floor((self._monotonic() - self._start_s) * self.sample_rate_hz)

    def seconds_until(self, sample_index: int) -> float:
        """Host seconds until ``due_index()`` reaches ``sample_index`` (0 when it has)."""
        return max(0.0, self._start_s + sample_index / self.sample_rate_hz - self._monotonic())
