"""The coils' duty-cycle limit: on for at most a fraction of any window of time.

The coils and their amplifiers heat while they drive; the limit holds for every window of
``window_samples`` on the device clock, not only per cycle, so that back-to-back cycles of a
sweep cannot add up to more. An excitation that would break it is not refused but delayed
(:meth:`DutyCycleLimit.earliest_start`); one that could never fit is refused.

Appending an interval [t, t + d) after all earlier ones, the on-time of a window is largest
for the window that ends at t + d (later windows lose old time and gain none; earlier ones
lose old time no faster than they gain new), so only that window is checked.
"""

from __future__ import annotations

import math


class DutyCycleLimit:
    """At most ``max_fraction`` of any ``window_samples`` consecutive samples with coils on."""

    def __init__(self, max_fraction: float, window_samples: int):
        self._intervals: list[tuple[int, int]] = []  # [on, off) sample indices, in order
        self.configure(max_fraction, window_samples)

    def configure(self, max_fraction: float, window_samples: int) -> None:
        """New limits; the history kept so far (one window of the old limits) counts on."""
        if not (math.isfinite(max_fraction) and 0.0 < max_fraction <= 1.0):
            raise ValueError(f"max_duty_cycle = {max_fraction!r} must be in (0, 1]")
        if window_samples < 1:
            raise ValueError(f"the duty-cycle window must hold at least one sample, got {window_samples!r}")
        self.max_fraction = float(max_fraction)
        self.window_samples = int(window_samples)

    @property
    def budget_samples(self) -> int:
        return math.floor(self.max_fraction * self.window_samples)

    def record(self, on_index: int, off_index: int) -> None:
        """The coils were on for samples [on_index, off_index)."""
        self._intervals.append((int(on_index), int(off_index)))
        horizon = off_index - self.window_samples
        self._intervals = [(a, b) for a, b in self._intervals if b > horizon]

    def on_samples_since(self, start_index: int) -> int:
        """Samples with coils on from ``start_index`` on."""
        return sum(max(0, b - max(a, start_index)) for a, b in self._intervals)

    def fraction(self, end_index: int) -> float:
        """Share of the window ending at ``end_index`` with the coils on."""
        start = end_index - self.window_samples
        return sum(max(0, min(b, end_index) - max(a, start)) for a, b in self._intervals) / self.window_samples

    def earliest_start(self, not_before: int, duration_samples: int) -> int:
        """The first sample ≥ ``not_before`` at which ``duration_samples`` of coil-on time
        keep the limit. ValueError if no start ever would."""
        spare = self.budget_samples - duration_samples
        if spare < 0:
            raise ValueError(
                f"an excitation of {duration_samples} samples exceeds the duty-cycle limit of "
                f"{self.max_fraction:g} × {self.window_samples} samples"
            )
        # The window of a start t begins at s = t + d − W; find the first s whose old on-time fits.
        low = not_before + duration_samples - self.window_samples
        high = max([low] + [b for _, b in self._intervals])
        while low < high:
            middle = (low + high) // 2
            if self.on_samples_since(middle) <= spare:
                high = middle
            else:
                low = middle + 1
        return low - duration_samples + self.window_samples
