"""The static-field supply's ramps as a driver session sees them: the commands it numbered and
sent, the answers that accept or refuse them, and the moment the samples reach a ramp's end.

A :class:`SupplyRamps` turns these into :class:`~mows.device.cycle.phases.SupplyEvent` s (a ramp
begins, a ramp ends, the driver ramped to zero itself) and calls each request's ``on_done``
once the device refused it or its samples have passed the ramp's end. It keeps no lock and
does no I/O: :class:`mows.device.stream.session.DeviceSession` owns it, sends the commands and calls it
under its lock.
"""

from __future__ import annotations

from collections.abc import Callable

from mows.device.cycle.phases import SupplyEvent
from mows.device.interface import CommandResult, FieldCurrentCommand

SUPPLY_COMMAND_IDS = 1 << 48  # supply commands are numbered from here: apart from the sequencer's

Done = Callable[[CommandResult], None]


class SupplyRamps:
    """The supply's ramps: sent, answered and reached; ``stamp_ns(sample_index)`` gives a
    sample's device stamp for the events."""

    def __init__(self, stamp_ns: Callable[[int], int]):
        self._stamp_ns = stamp_ns
        self._last_id = SUPPLY_COMMAND_IDS
        self._waiting: dict[int, tuple[Done, FieldCurrentCommand]] = {}  # sent, not answered
        self._ramping: list[tuple[CommandResult, Done, float]] = []  # answered, not reached
        self._latest: int | None = None  # the ramp that sets the supply (none after a ramp to zero)
        self._events: list[SupplyEvent] = []  # not yet handed to the streaming thread
        self.state: SupplyEvent | None = None  # the last event, for /diagnostics

    def command(self, at_sample_index: int, current_a: float) -> FieldCurrentCommand:
        """A new command that ramps the supply to ``current_a`` from ``at_sample_index``."""
        self._last_id += 1
        return FieldCurrentCommand(self._last_id, at_sample_index, float(current_a))

    def sent(self, command: FieldCurrentCommand, on_done: Done) -> None:
        self._waiting[command.command_id] = (on_done, command)

    def answers(self, result: CommandResult) -> bool:
        """Whether ``result`` answers a supply command (not one of the sequencer's)."""
        return result.command_id in self._waiting

    def answered(self, result: CommandResult, next_index: int) -> None:
        """The device accepted or refused a supply command; ``next_index``: the sample after the newest received."""
        done, command = self._waiting.pop(result.command_id)
        if not result.accepted:
            done(result)
            return
        self._latest = command.command_id
        start = command.at_sample_index
        self.event(SupplyEvent(start, self._stamp_ns(start), command.current_a, True))
        self._ramping.append((result, done, command.current_a))
        self.reached(next_index)

    def reached(self, next_index: int) -> None:
        """Samples up to ``next_index`` (exclusive) have arrived: the ramps that ended before it are done."""
        reached = [ramp for ramp in self._ramping if ramp[0].applied_sample_index < next_index]
        self._ramping = [ramp for ramp in self._ramping if ramp[0].applied_sample_index >= next_index]
        for result, done, current_a in reached:
            if result.command_id == self._latest:  # not overtaken by a later ramp or a ramp to zero
                end = result.applied_sample_index
                self.event(SupplyEvent(end, self._stamp_ns(end), current_a, False))
            done(result)

    def dropped(self, next_index: int, reason: str) -> None:
        """The driver ramped the supply to zero itself: no ramp that waits sets it any more, and
        when it is back at zero is not known (a ramp, not a steady state). A supply that is steady
        at zero, or was never set, stays so: nothing ramps, and no flag is raised."""
        self._latest = None
        at_zero = self.state is None or (self.state.current_a == 0.0 and not self.state.ramping)
        if at_zero and not self._waiting and not self._ramping:
            return
        self.event(SupplyEvent(next_index, self._stamp_ns(next_index), 0.0, True, reason))

    def event(self, event: SupplyEvent) -> None:
        """Record ``event`` (one of ours, or one replayed from a recording)."""
        self._events.append(event)
        self.state = event

    def take_events(self) -> list[SupplyEvent]:
        """The events since the last call, in order."""
        events, self._events = self._events, []
        return events
