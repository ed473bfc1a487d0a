"""Progress of the lab's long work, for a front end to show; silent unless someone listens.

The lab's loops say what they are doing (:func:`stage`: the task, how many of its items are
done, of how many) and every evaluation of a model on a table is counted (:func:`evaluated`):
the work between two stages (a fit on thousands of rows) still moves. ``mows lab`` shows both
as a progress bar on a terminal (:mod:`mows.cli.lab`). The listener is held in a context
variable, so an analysis elsewhere in the process (the mapper node's) reports nothing to it.
Imports no lab module.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from contextvars import ContextVar
from typing import Protocol


class Listener(Protocol):
    def stage(self, task: str, done: int, total: int) -> None: ...

    def evaluated(self) -> None: ...


_listener: ContextVar[Listener | None] = ContextVar("mows_lab_progress", default=None)


@contextlib.contextmanager
def listening(listener: Listener) -> Iterator[Listener]:
    """Report the lab's progress inside the ``with`` block to ``listener``."""
    token = _listener.set(listener)
    try:
        yield listener
    finally:
        _listener.reset(token)


def stage(task: str, done: int, total: int) -> None:
    """``done`` of the ``total`` items of ``task`` are finished."""
    listener = _listener.get()
    if listener is not None:
        listener.stage(task, done, total)


def evaluated() -> None:
    """One evaluation of a model on a table (the unit of the lab's cost)."""
    listener = _listener.get()
    if listener is not None:
        listener.evaluated()
