"""The sample rate a driver actually receives: samples counted per host second over a sliding
window, for /diagnostics (a device or link that falls behind shows here before gaps do)."""

from __future__ import annotations

import collections

RATE_WINDOW_S = 5.0  # the achieved sample rate is measured over this much host time


class RateMeter:
    """Arrivals of samples at host times (s), from one monotonic clock."""

    def __init__(self) -> None:
        self._first_s: float | None = None
        self._arrivals: collections.deque[tuple[float, int]] = collections.deque()  # (host time, samples)

    def add(self, now_s: float, n: int) -> None:
        """``n`` samples arrived at host time ``now_s``."""
        if self._first_s is None:
            self._first_s = now_s
        self._arrivals.append((now_s, n))
        while now_s - self._arrivals[0][0] > RATE_WINDOW_S:
            self._arrivals.popleft()

    def rate_hz(self, now_s: float) -> float | None:
        """Samples received per host second over the last RATE_WINDOW_S; None in the first
        RATE_WINDOW_S of samples, when the stream catches up with the time its start took."""
        if self._first_s is None or now_s - self._first_s < RATE_WINDOW_S or len(self._arrivals) < 2:
            return None
        span = self._arrivals[-1][0] - self._arrivals[0][0]
        return sum(n for _, n in list(self._arrivals)[1:]) / span if span > 0 else None
