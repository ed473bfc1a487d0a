"""What every stage's result offers, whatever it computed: the ring-down fit
(:class:`mows.estimate.ringdown.RingdownFit`), the sweep decomposition
(:class:`mows.sweep.decomposition.Decomposition`) and the lab's fit
(:class:`mows.lab.model.least_squares.FitResult`).

``ok`` says whether its numbers may be used; ``status`` says why not, as a member of the
stage's own status enum (compare it by name, ``result.status is FitStatus.OK``, never with a
bare number); ``report()`` is one human-readable line or block with the values and their
uncertainties.
"""

from __future__ import annotations

import enum
from typing import Protocol, runtime_checkable


@runtime_checkable
class Result(Protocol):
    @property
    def ok(self) -> bool: ...

    @property
    def status(self) -> enum.Enum: ...

    def report(self) -> str: ...
