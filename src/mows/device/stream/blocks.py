"""Cutting the sample stream into published blocks, with gaps shown and counted.

Blocks hold ``block_samples`` consecutive samples. A block never spans a gap: when samples
are missing, the block being filled is published short, the gap is counted, and the next
block's sequence number jumps by one more than the blocks' worth of samples lost (at least
2), so that a subscriber sees the loss in ``sequence`` as well as in ``first_sample_index``.
Nothing is interpolated or filled in. A jump backwards is the device's clock starting again:
the blocks after it carry the next ``epoch``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.records.samples import SampleBlock


class BlockAssembler:
    """Sample blocks as the device sent them in, blocks of ``block_samples`` numbered by
    ``sequence`` out (``block_samples`` may change between blocks)."""

    def __init__(self, block_samples: int, first_epoch: int = 0):
        self.block_samples = int(block_samples)
        self.first_epoch = int(first_epoch)  # the epoch of this assembler's first block
        self.gaps = 0  # discontinuities of the sample index
        self.missing_samples = 0  # samples lost in them: forward jumps, and a restarted device's
        # samples before the first received (at least that many)
        self.restarts = 0  # jumps backwards: the device's counter started again
        self.samples = 0
        self.saturated_samples = 0  # samples with any channel saturated
        self._parts: list[SampleBlock] = []
        self._pending = 0
        self._expected: int | None = None
        self._sequence = 0

    def add(self, chunk: SampleBlock) -> list[SampleBlock]:
        """The blocks completed by ``chunk``."""
        blocks = []
        if self._expected is not None and chunk.first_sample_index != self._expected:
            blocks += self.flush()
            self._sequence += self._count_gap(chunk.first_sample_index, chunk.first_sample_index - self._expected)
        self._expected = chunk.end_index
        self.samples += len(chunk)
        self.saturated_samples += int(np.count_nonzero(chunk.saturated.any(axis=1)))
        self._parts.append(chunk)
        self._pending += len(chunk)
        while self._pending >= self.block_samples:
            blocks.append(self._cut(self.block_samples))
        return blocks

    @property
    def epoch(self) -> int:
        """The device clock's epoch now: the first one plus the restarts seen since."""
        return self.first_epoch + self.restarts

    def flush(self) -> list[SampleBlock]:
        """The block being filled, short, if it holds any samples."""
        return [self._cut(self._pending)] if self._pending else []

    def _count_gap(self, first: int, jump: int) -> int:
        """Count a jump of the sample index; the extra sequence steps it takes. After a restart
        the device counts from 0 again: the samples it took before the first one received are
        missing (those its old life took after the last one received cannot be known)."""
        self.gaps += 1
        if jump < 0:
            self.restarts += 1
            self.missing_samples += first
            return 1
        self.missing_samples += jump
        return max(1, math.ceil(jump / self.block_samples))

    def _cut(self, n: int) -> SampleBlock:
        """A block of the first ``n`` pending samples."""
        taken, rest, need = [], [], n
        for part in self._parts:
            if need >= len(part):
                taken.append(part)
                need -= len(part)
            elif need > 0:
                taken.append(part.rows(0, need))
                rest.append(part.rows(need, len(part)))
                need = 0
            else:
                rest.append(part)
        self._parts, self._pending = rest, self._pending - n
        block = dataclasses.replace(SampleBlock.concatenate(taken, sequence=self._sequence), epoch=self.epoch)
        self._sequence += 1
        return block
