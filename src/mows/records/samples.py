"""One block of consecutive magnetometer samples: the type every stage passes on, from the
device (simulated, serial or replayed) through the published stream to the ring-down fit.

Row i of ``samples_t`` was taken at device time ``stamp_ns + i / sample_rate_hz`` (integer
nanoseconds, REP-145: the stamp is the time of the first sample) and is device sample
``first_sample_index + i``. ``samples_t`` (n, channels) tesla; ``saturated`` (n, channels)
flags samples clipped at the sensor's range (their value is not a measurement). ``sequence``
numbers published blocks (0 until a block assembler numbers them); ``epoch`` counts the device
clock's restarts (indices and stamps of two epochs do not compare).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable

import numpy as np

from mows.records.stamps import NS_PER_S


@dataclasses.dataclass(frozen=True, eq=False)
class SampleBlock:
    """Consecutive samples of one device. A block no device could send raises ValueError."""

    first_sample_index: int
    stamp_ns: int
    sample_rate_hz: float
    samples_t: np.ndarray
    saturated: np.ndarray
    sequence: int = 0
    epoch: int = 0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.sample_rate_hz) and self.sample_rate_hz > 0):
            raise ValueError(f"sample rate {self.sample_rate_hz!r} Hz is not a positive number")
        if not isinstance(self.stamp_ns, (int, np.integer)):
            raise ValueError(f"stamp {self.stamp_ns!r} is not integer nanoseconds")
        shape = np.shape(self.samples_t)
        if len(shape) != 2 or shape[1] == 0:
            raise ValueError(f"samples of shape {shape}: expected (samples, channels ≥ 1)")
        if np.shape(self.saturated) != shape:
            raise ValueError(f"saturation flags of shape {np.shape(self.saturated)} for samples of shape {shape}")

    def __len__(self) -> int:
        return int(self.samples_t.shape[0])

    @property
    def end_index(self) -> int:
        """The sample index after the last one."""
        return self.first_sample_index + len(self)

    def stamp_of(self, sample_index: int) -> int:
        """Device time of ``sample_index`` on this block's clock, ns (the clock is linear in
        samples)."""
        return self.stamp_ns + round((sample_index - self.first_sample_index) * NS_PER_S / self.sample_rate_hz)

    def index_at(self, stamp_ns: int) -> int:
        """The sample index taken at device time ``stamp_ns`` (nearest sample)."""
        return self.first_sample_index + round((stamp_ns - self.stamp_ns) * self.sample_rate_hz / NS_PER_S)

    def rows(self, start: int, stop: int) -> SampleBlock:
        """Rows [start, stop) as a block of their own, restamped."""
        return dataclasses.replace(
            self,
            first_sample_index=self.first_sample_index + start,
            stamp_ns=self.stamp_of(self.first_sample_index + start),
            samples_t=self.samples_t[start:stop],
            saturated=self.saturated[start:stop],
        )

    @staticmethod
    def concatenate(blocks: Iterable[SampleBlock], sequence: int | None = None) -> SampleBlock:
        """One block of consecutive ``blocks`` (the first one's index, stamp and rate)."""
        blocks = list(blocks)
        first = blocks[0]
        return dataclasses.replace(
            first,
            samples_t=np.concatenate([b.samples_t for b in blocks]),
            saturated=np.concatenate([b.saturated for b in blocks]),
            sequence=first.sequence if sequence is None else sequence,
        )
