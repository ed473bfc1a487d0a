"""Who waits for what a node runs, and what its cancels report: I/O-free, fed events.

A service or action server is not told who sent a request. So a request remembers the request
writers (DDS endpoints, by GID) of the clients of the interface it was asked through when it
began, and the caller looks at the graph again now and then; once none of those writers is
there any more, nobody can take the request's answer and it is cancelled (:class:`Requesters`,
the one rule for the driver's cycles, the mapper's sweeps and the calibrator's runs; the graph
is read by ``mows_ros.requesters``). A writer is in the graph as soon as DDS has matched it,
which a request needs to arrive at all, yet the graph may show it a moment after the request
came: should none be seen for :data:`UNSEEN_S` after the request, the requester left before the
graph could show it. While another of those clients stays (a mapper beside a command-line
client), the request runs on: the rule never cancels one whose requester may still be there.

:class:`SweepRequests` is the mapper's bookkeeping over its :class:`mows.sweep.runner.SweepRunner`:
the running sweep's requesters, the client's cancel of a sweep or of a workspace map, the node's
own cancel once the requesters have gone, and what each ending reports (its log line, the
action's end: :func:`goal_ending`). The runner counts the cancels for /diagnostics. The node
carries out its answers: a :class:`Cancel` (the running cycle cancelled, the awaited fits given
up), a :class:`LogLine`, an :class:`Ending`.
"""

import dataclasses
import enum
from collections.abc import Sequence

from mows.sweep.events import SweepOutcome, SweepStep
from mows.sweep.runner import SweepRunner, SweepState

UNSEEN_S = 2.0  # far beyond the graph's lag behind DDS matching (milliseconds)


class Requesters:
    """The clients that may wait for one request, asked through one of ``service_names`` (an
    action's: its ``/_action/send_goal``) at ``asked_s`` on a steady clock, when the graph showed
    the request writers ``seen``."""

    def __init__(self, service_names: Sequence[str], seen: frozenset[bytes], asked_s: float):
        self.service_names = tuple(service_names)
        self.seen, self._asked_s = frozenset(seen), asked_s

    @property
    def reason(self) -> str:
        """Why the request is cancelled once they are gone (the first name: the node's own)."""
        return f"every node that asked for it through {self.service_names[0]} has left"

    def gone(self, present: frozenset[bytes], now_s: float) -> bool:
        """Whether every client that may wait for the request has left, the graph showing the
        request writers ``present`` at ``now_s``. Those first shown after the request are its
        requesters when none were shown at the start."""
        if not self.seen:
            self.seen = frozenset(present)
            return not present and now_s - self._asked_s > UNSEEN_S
        return not self.seen & present


class Ending(enum.StrEnum):
    """How an action goal ends (the action's terminal states)."""

    SUCCEEDED = "succeeded"
    CANCELED = "canceled"
    ABORTED = "aborted"


def goal_ending(succeeded: bool, cancelled: bool, cancel_requested: bool) -> Ending:
    """Cancelled (whatever else) as its client asked, else succeeded or aborted. A goal the node
    cancelled itself, its client gone, was never asked to cancel and cannot end CANCELED (the
    action's state machine): it ends aborted."""
    if cancelled:
        return Ending.CANCELED if cancel_requested else Ending.ABORTED
    return Ending.SUCCEEDED if succeeded else Ending.ABORTED


class Severity(enum.StrEnum):
    INFO = "info"
    WARNING = "warning"


@dataclasses.dataclass(frozen=True)
class LogLine:
    severity: Severity
    text: str


@dataclasses.dataclass(frozen=True)
class Cancel:
    """A cancel to carry out: the running cycle (if any) cancelled, and ``step``, the runner's
    answer to the awaited fits given up (None: none awaited), handed to whoever awaits them.
    ``log`` is what a cancel the node made itself says (None for a client's)."""

    step: SweepStep | None = None
    log: LogLine | None = None


class SweepRequests:
    """The requests ``runner`` serves: its sweep's requesters and the cancels of a sweep goal and
    of a workspace map goal (whose sweeps the runner runs one after another)."""

    def __init__(self, runner: SweepRunner) -> None:
        self._runner = runner
        self._requesters: Requesters | None = None  # the running sweep's, while it is watched
        self.mapping = False  # whether a workspace map goal runs
        self.map_cancelled = False  # whether the running (or last) map was cancelled, or its client left

    # --- who waits ------------------------------------------------------------------------
    def watch(self, service_names: Sequence[str], seen: frozenset[bytes], now_s: float) -> None:
        """The started sweep was asked for through ``service_names`` (a map's sweep: the map's),
        whose request writers the graph shows as ``seen`` at ``now_s``. A map's sweeps after its
        first wait for the requesters of the map's first."""
        if not (self.mapping and self._requesters is not None):
            self._requesters = Requesters(service_names, seen, now_s)

    @property
    def service_names(self) -> tuple[str, ...]:
        """The names whose request writers :meth:`on_graph` wants (none while nothing is watched)."""
        return () if self._requesters is None else self._requesters.service_names

    def on_graph(self, present: frozenset[bytes], now_s: float) -> Cancel | None:
        """The graph shows the request writers ``present`` at ``now_s``: the running sweep's
        cancel once every requester has gone, the first time only (None otherwise). Nobody waits
        for the map either, then: it takes no further sweep."""
        requesters = self._requesters
        if requesters is None or self._runner.state == SweepState.IDLE or self._runner.cancelled():
            return None
        if not requesters.gone(present, now_s):
            return None
        self._runner.cancel(requesters.reason)
        self.map_cancelled = self.map_cancelled or self.mapping
        warning = f"sweep cancelled, its cycle with it: {requesters.reason}"
        return Cancel(self._runner.fits_time_up(), LogLine(Severity.WARNING, warning))

    # --- the sweep goal -------------------------------------------------------------------
    def sweep_refusal(self) -> str | None:
        """Why a client's sweep goal is refused now, or None: a running workspace map takes each
        of its sweeps itself, and one started beside it would leave the map's next sweep none."""
        return "a workspace map is running" if self.mapping else None

    def on_cancel(self) -> Cancel | None:
        """The client cancels its sweep goal: the cancel, or None (refused) once the sweep has
        ended (its map is being published or the goal is over)."""
        if self._runner.state == SweepState.IDLE:
            return None
        self._runner.cancel()
        return Cancel(self._runner.fits_time_up())

    def ended(self, outcome: SweepOutcome) -> LogLine | None:
        """The sweep ended with ``outcome`` (watched no more, unless a map's): what the log says of it."""
        if not self.mapping:
            self._requesters = None
        if outcome.cancelled:
            return LogLine(Severity.INFO, f"sweep {self._runner.last_cancel}")
        if not outcome.ok:
            return LogLine(Severity.WARNING, f"sweep aborted: {outcome.message}")
        return None

    def abandon(self, reason: str) -> None:
        """The sweep cannot go on (an exception): it ends failed with ``reason`` (nothing, once
        it has ended), watched no more unless a map's."""
        self._runner.abandon(reason)
        if not self.mapping:
            self._requesters = None

    # --- the workspace map goal -----------------------------------------------------------
    def start_map(self, probes: int) -> str | None:
        """Why a workspace map of ``probes`` probes is refused now, or None: it starts, and runs
        until :meth:`map_ended`."""
        if self._runner.state != SweepState.IDLE:
            return "a sweep is running"
        if self.mapping:
            return "a workspace map is running"
        if probes > 1:
            return f"the arm carries one probe; the mapper has {probes}"
        self.mapping, self.map_cancelled = True, False
        return None

    def on_cancel_map(self) -> Cancel | None:
        """The client cancels its map goal: no further sweep, the running one cancelled; None
        (refused) once the map has ended."""
        if not self.mapping:
            return None
        self.map_cancelled = True
        return self.on_cancel() or Cancel()

    def map_ended(self) -> None:
        """The map goal has ended (``map_cancelled`` says whether it was cancelled)."""
        self.mapping, self._requesters = False, None
