"""What a running measurement cycle waits for and what it records, apart from the sequencer
that drives it (:class:`mows.device.cycle.sequencer.CycleSequencer`).

A running cycle is a generator (:data:`Run`) that yields a :class:`Reach` (samples up to an
index) or an :class:`Answer` (the device's result of a command), and raises
:class:`CycleAborted` when the device refuses or does not answer. A :class:`Recording` keeps a
ring-down's samples as they arrive, and knows whether any went missing.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Generator

import numpy as np

from mows.device.cycle.phases import CycleOutcome
from mows.device.interface import Command, CommandResult
from mows.records.samples import SampleBlock


class CycleAborted(Exception):
    """Ends a running cycle: the device refused or did not answer a command."""


@dataclasses.dataclass(frozen=True)
class Reach:
    """Resume once every sample before ``index`` has been received."""

    index: int


@dataclasses.dataclass(frozen=True)
class Answer:
    """Resume with the result of ``command``; abort after sample ``deadline_index``."""

    command: Command
    deadline_index: int


class Recording:
    """The samples [start, end) as they arrive; ``complete`` if none was missing."""

    def __init__(self, start: int, end: int):
        self.start, self.end = start, end
        self._parts: list[SampleBlock] = []
        self._next = start

    def add(self, chunk: SampleBlock) -> None:
        lo, hi = max(chunk.first_sample_index, self.start), min(chunk.end_index, self.end)
        # Samples after a gap are not kept: the recording stays incomplete.
        if lo < hi and lo == self._next:
            self._parts.append(chunk)
            self._next = hi

    @property
    def complete(self) -> bool:
        return self._next == self.end

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        rows = [
            (
                max(c.first_sample_index, self.start) - c.first_sample_index,
                min(c.end_index, self.end) - c.first_sample_index,
            )
            for c in self._parts
        ]
        return (
            np.concatenate([c.samples_t[a:b] for c, (a, b) in zip(self._parts, rows)]),
            np.concatenate([c.saturated[a:b] for c, (a, b) in zip(self._parts, rows)]),
        )


# A running cycle is a generator: it yields what it waits for and is sent, on resuming, the
# command result it waited for (None after a Reach).
Run = Generator[Reach | Answer, CommandResult | None, CycleOutcome]
