"""A supply's ramps on the card's sample clock: the staircase of each new current within the slew
limit, rounded to the resolution, queued after any ramp already under way, and handed out as the
input stream reaches each step's sample. Pure bookkeeping over :class:`mows.physics.supply.SupplyLimits`;
the instrument it drives is :mod:`mows.device.instruments.scpi`.
"""

from __future__ import annotations

from mows.physics.supply import SupplyLimits


class SupplySchedule:
    """The ramps of a supply on the sample clock, as :class:`mows.device.simulated.scheduled.ScheduledDevice`
    walks them: each new current is checked against the cap, rounded to the resolution and reached
    by a staircase within the slew limit that starts after any ramp already queued."""

    def __init__(self, limits: SupplyLimits, sample_rate_hz: float):
        self.limits = limits
        self.sample_rate_hz = sample_rate_hz
        self.target_a = 0.0  # where the queued steps end
        self.current_a = 0.0  # the last step handed out
        self.last_index = -1  # its sample
        self._steps: list[tuple[int, float]] = []  # (sample index, current), in order

    def ramp(self, at_index: int, next_index: int, current_a: float) -> int:
        """Queue the staircase to ``current_a`` from ``at_index`` (not before ``next_index`` nor the
        end of a queued ramp); the sample of its last step. ValueError above the cap."""
        target = self.limits.check(current_a)
        start = max(int(at_index), int(next_index), self._steps[-1][0] + 1 if self._steps else 0)
        return self._queue(start, self.target_a, target)

    def to_zero(self, next_index: int) -> int:
        """Drop the queued steps and ramp down from the present current; the sample it reaches zero."""
        self._steps = []
        return self._queue(int(next_index), self.current_a, 0.0)

    def _queue(self, start: int, from_a: float, to_a: float) -> int:
        steps = [(start + round(t * self.sample_rate_hz), a) for t, a in self.limits.ramp(from_a, to_a)]
        self._steps += steps
        self.target_a = to_a
        return steps[-1][0]

    def drop(self) -> None:
        """Drop the queued steps: the supply was switched off at zero."""
        self._steps = []
        self.target_a = self.current_a = 0.0

    def due(self, next_index: int) -> list[float]:
        """The steps whose sample is before ``next_index``, in order (each once)."""
        due = [(index, a) for index, a in self._steps if index < next_index]
        self._steps = [(index, a) for index, a in self._steps if index >= next_index]
        if due:
            self.last_index, self.current_a = due[-1]
        return [a for _, a in due]

    @property
    def ramping(self) -> bool:
        return bool(self._steps)
