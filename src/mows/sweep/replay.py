"""A recorded session's sweeps made again, offline: the cycles a bag's excitations announce and
the ring-down fits recorded beside them (or fitted again from its raw stream) fed through the
mapper's own state machine (:class:`mows.sweep.runner.SweepRunner`) as the mapper fed them live.
A recording of the graph (the driver's ``record_path``, docs/driver.md) thus gives back the
map the graph published, for one probe or several, with no node running (``mows map BAG``).

A bag's measurement cycles are those whose RINGDOWN phases it recorded (tuning ones are not
measurements); each is one orientation of the stage, at the phase's ``theta0_rad`` (the stage's;
each probe's own θ0 is in its fits), answered with the ring-downs recorded. Each recorded
SweepDecomposition names its sweep's cycles (``cycle_ids``): a sweep is those, and cycles run
before or between sweeps (another client's, a cancelled sweep's) are left out; cycles after the
last one (a sweep the recording stopped in, or a bag without sweeps) are one more. A recording
made before the mapper named them is cut by the sweeps' stamps instead, each that of its
sweep's last ring-down. What the recording does not hold is the caller's to say: the probes and their
constants, the model and whether f00 is free (the mapper's parameters).

Imports: the sweep's own modules, the estimate's stream results and the device's bag reader.
"""

from __future__ import annotations

import collections
import dataclasses
import os
from collections.abc import Iterable, Sequence

from mows.device.cycle.phases import Phase
from mows.device.recording.bags import read_bag
from mows.records import stamps
from mows.sweep.events import CycleAnswer, SweepFit, SweepGoal, SweepOutcome, SweepSettings, SweepStep
from mows.sweep.runner import SweepRunner

EXCITATION_TOPIC, RINGDOWN_TOPIC, SWEEP_TOPIC = "/mows/excitation", "/mows/ringdown", "/mows/sweep"


@dataclasses.dataclass(frozen=True)
class RecordedCycle:
    """One measurement cycle as the bag's excitations announced it: the stage's θ0, the
    ring-downs it recorded and the device stamp of its last one."""

    cycle_id: int
    theta0_rad: float
    ringdowns: int
    stamp_ns: int


@dataclasses.dataclass(frozen=True)
class RecordedSession:
    """What a bag holds of the sweeps made while it recorded."""

    cycles: tuple[RecordedCycle, ...]
    fits: tuple[SweepFit, ...]  # the estimator's, as recorded
    sweep_stamps_ns: tuple[int, ...]  # each recorded sweep's, in order
    sweep_cycle_ids: tuple[tuple[int, ...], ...] = ()  # each recorded sweep's cycles, when it names them

    def sweeps(self) -> list[tuple[RecordedCycle, ...]]:
        """The cycles of each recorded sweep, in order (module docstring)."""
        if not self.sweep_cycle_ids:
            return self._cut_by_stamps()[0]
        by_id = {c.cycle_id: c for c in self.cycles}
        named = [tuple(by_id[i] for i in ids if i in by_id) for ids in self.sweep_cycle_ids]
        return [group for group in named if group]

    def after_last(self) -> tuple[RecordedCycle, ...]:
        """The cycles after the last recorded sweep's (all of them when none was recorded): a
        sweep the recording stopped in, or another client's cycles."""
        if not self.sweep_cycle_ids:
            return self._cut_by_stamps()[1]
        named = self._named()
        end_ns = max((c.stamp_ns for c in self.cycles if c.cycle_id in named), default=-1)
        return tuple(c for c in self.cycles if c.cycle_id not in named and c.stamp_ns > end_ns)

    def left_out(self) -> tuple[RecordedCycle, ...]:
        """The cycles before or between the recorded sweeps that are none of theirs (another
        client's, a cancelled sweep's); none in a recording cut by stamps."""
        after = set(self.after_last())
        named = self._named()
        return tuple(c for c in self.cycles if self.sweep_cycle_ids and c.cycle_id not in named and c not in after)

    def _named(self) -> set[int]:
        return {i for ids in self.sweep_cycle_ids for i in ids}

    def _cut_by_stamps(self) -> tuple[list[tuple[RecordedCycle, ...]], tuple[RecordedCycle, ...]]:
        """Each recorded sweep's cycles, those whose last ring-down came no later than its stamp,
        and the cycles after the last."""
        groups: list[tuple[RecordedCycle, ...]] = []
        cycles = list(self.cycles)
        for stamp in self.sweep_stamps_ns:
            mine = [c for c in cycles if c.stamp_ns <= stamp]
            cycles = cycles[len(mine) :]
            if mine:
                groups.append(tuple(mine))
        return groups, tuple(cycles)


def read_session(path: str | os.PathLike[str]) -> RecordedSession:
    """The cycles, fits and sweeps a bag recorded (``ValueError`` when it announced no
    measurement ring-down: there is no sweep to make again)."""
    ringdowns: dict[int, list] = {}  # each cycle's RINGDOWN announcements, in order
    fits, sweeps = [], set()
    named: dict[int, tuple[int, ...]] = {}  # each recorded sweep's cycles, by sweep id
    for item in read_bag(path, topics=(EXCITATION_TOPIC, RINGDOWN_TOPIC, SWEEP_TOPIC)):
        message = item.message
        if item.topic == RINGDOWN_TOPIC:
            fits.append(SweepFit.from_message(message))
        elif item.topic == SWEEP_TOPIC:
            sweeps.add(stamps.nanoseconds(message.header.stamp))
            # one message per probe of a sweep, all naming its cycles (none in an older recording)
            named.setdefault(message.sweep_id, tuple(int(i) for i in getattr(message, "cycle_ids", ())))
        elif message.phase == Phase.RINGDOWN and not message.tuning:
            ringdowns.setdefault(message.cycle_id, []).append(message)
    if not ringdowns:
        raise ValueError(f"{path}: no measurement ring-down announced on {EXCITATION_TOPIC}: no sweep to make again")
    cycles = tuple(
        RecordedCycle(
            cycle_id,
            float(phases[0].theta0_rad),
            len({p.repeat_index for p in phases}),
            max(stamps.nanoseconds(p.header.stamp) for p in phases),
        )
        for cycle_id, phases in ringdowns.items()
    )
    ids = tuple(named[k] for k in sorted(named)) if all(named.values()) else ()
    return RecordedSession(tuple(sorted(cycles, key=lambda c: c.stamp_ns)), tuple(fits), tuple(sorted(sweeps)), ids)


def replay_sweep(cycles: Sequence[RecordedCycle], fits: Iterable[SweepFit], settings: SweepSettings) -> SweepOutcome:
    """The sweep of ``cycles`` with ``fits`` (those of other cycles are not its), run through
    :class:`SweepRunner` with ``settings`` as the mapper runs it: each cycle
    answered with its recorded ring-downs, then its fits; a cycle with fewer fits than it
    recorded goes on with those there are, as the mapper does once their time is up.
    ``ValueError`` when the runner refuses the sweep (e.g. too few orientations)."""
    if not cycles:
        raise ValueError("no cycle to make a sweep of")
    by_cycle = collections.defaultdict(list)
    for fit in fits:
        by_cycle[fit.cycle_id].append(fit)
    runner = SweepRunner()
    runner.start(SweepGoal(tuple(c.theta0_rad for c in cycles), max(c.ringdowns for c in cycles)), settings)
    pending = iter(cycles)
    step = runner.begin()
    while step.finished is None:
        if step.turn is not None:
            step = runner.on_turned()
        elif step.run_cycle is not None:
            step = _answered(runner, next(pending), by_cycle)
        elif step.decompose is not None:
            step = runner.on_decomposed(step.decompose())
        else:
            raise AssertionError(f"the runner waits for nothing a recording holds: {step}")
    return step.finished


def _answered(runner: SweepRunner, cycle: RecordedCycle, by_cycle: dict[int, list[SweepFit]]) -> SweepStep:
    """The runner's next step once ``cycle`` answered and its recorded fits came."""
    step = runner.on_cycle(CycleAnswer(cycle.cycle_id, cycle.ringdowns))
    if step.run_cycle is not None or step.decompose is not None or step.finished is not None:
        return step
    for fit in by_cycle.pop(cycle.cycle_id, ()):
        if (collected := runner.on_fit(fit)) is not None:
            return collected
    timed_out = runner.fits_time_up()
    assert timed_out is not None  # the runner awaits this cycle's fits
    return timed_out
