"""The bench's field supply on a thread of its own, so that its I/O never holds up the card's
stream: a supply on the LAN answers each exchange in milliseconds, and a ramp's steps written
from the stream thread (two exchanges every 10 ms step) made the host fall behind the card.

:class:`SupplyLine` owns the :class:`mows.device.instruments.scpi.ScpiSupply` and does, in order,
what the backend hands it: the steps of a ramp (the supply prepared again first when it was
switched off; never closer than the ramp's 10 ms step, so that the slew limit holds however late
they come), the switch-off at the end of an emergency stop's ramp to zero, and the read-back
``settle_s`` after a ramp's last step, in the supply's own time from the write, stamped with that
step's sample (:class:`Readback`): a read-back is judged only against the step it follows. While
the output should be on it is read back every ``WATCH_S`` too: an output that went off by itself
(a tripped over-voltage protection) is a failure, as is every error of the supply. Every
exchange (one message to the supply) has a deadline: one that has not ended ``deadline_s``
after it was sent has hung (VISA's own timeout did not end it), and the backend faults on it as
on an error. On a fault the line drops what waits and ramps the supply to zero within its slew
limit in host time, switches it off and reads it back (:meth:`SupplyLine.make_safe`): waited
for as long as the supply answers (a ramp on a loaded host takes what it takes), each exchange
under the same deadline.
"""

from __future__ import annotations

import collections
import dataclasses
import math
import threading
import time
from collections.abc import Callable

from mows.device.instruments.scpi import ScpiSupply, SupplyError
from mows.physics.supply import RAMP_STEP_S

WATCH_S = 1.0  # the output is read back this often while it should be on


@dataclasses.dataclass(frozen=True)
class Readback:
    """The supply as it read back: ``current_a`` and ``output`` ('on', 'off'; '' for a model
    that cannot say), after the step written for sample ``step_index`` (-1: none yet), read at
    ``read_s`` (time.monotonic())."""

    current_a: float
    output: str
    step_index: int
    read_s: float


NOT_READ = Readback(math.nan, "", -1, math.nan)


class SupplyLine:
    """``supply``'s I/O on a worker thread; each exchange ends within ``deadline_s``. The worker
    calls ``started`` first (the backend's real-time priority, :mod:`mows.device.backends.realtime`)."""

    def __init__(self, supply: ScpiSupply, deadline_s: float, started: Callable[[], object] = lambda: None):
        self.supply = supply
        self.deadline_s = deadline_s
        self.readback = NOT_READ
        self.current_a = 0.0  # the last current the supply accepted
        self.off = False  # switched off (a fault, an emergency stop): prepared again before its next step
        self._failure = ""  # the first failure not yet taken by the backend
        self._jobs: collections.deque[Callable[[], None]] = collections.deque()
        self._settled_at: tuple[float, int] | None = None  # (time, step) of the read-back a ramp's end is due
        self._watch_at_s = math.inf
        self._stopping = False
        self._working = False  # a job under way
        self._step_index = -1
        self._stepped_s = -math.inf  # when the last step was written
        self._safe_job: Callable[[], None] | None = None
        self._condition = threading.Condition()
        self._started = started
        self._thread = threading.Thread(target=self._run, name="mows-supply", daemon=True)
        self._thread.start()

    # --- what the backend hands over (never blocks) -------------------------------------------
    def step(self, current_a: float, index: int, last: bool) -> None:
        """Write ``current_a``, the step of sample ``index``; read back after it when ``last``."""
        self._queue(lambda: self._write_step(current_a, index, last))

    def switch_off(self) -> None:
        """After the steps queued (an emergency stop's ramp to zero): the output off and read back."""
        self._queue(self._switch_off)

    def failure(self) -> str:
        """What went wrong since the last call ('' : nothing): an error, a hung exchange."""
        with self._condition:
            failure, self._failure = self._failure, ""
        if not failure and self._hung():
            failure = f"the supply did not answer within {self.deadline_s:g} s"
        return failure

    def _hung(self) -> bool:
        """The message under way has not ended ``deadline_s`` after it was sent."""
        since = self.supply.message_since_s
        return since is not None and time.monotonic() - since > self.deadline_s

    def _wait(self, done: Callable[[], bool]) -> bool:
        """Wait until ``done()`` for as long as the supply answers (a ramp on a loaded host takes
        what it takes); False when a message hung or the worker is gone."""
        while not done():
            if self._hung() or not self._thread.is_alive():
                return done()
            time.sleep(RAMP_STEP_S)
        return True

    def stats(self, target_a: float) -> dict:
        """The supply for the driver's diagnostics: its identity, ``target_a`` and its last read-back."""
        readback = self.readback
        return {
            "supply": self.supply.identity,
            "supply_target_a": target_a,
            "supply_readback_a": readback.current_a,
            "supply_output": readback.output,
            "supply_readback_step": readback.step_index,
        }

    def closed_state(self) -> str:
        """The supply as it read back last (after its ramp to zero and switch-off on close)."""
        return f"supply {self.readback.output or 'output not read back'} at {self.readback.current_a:.4f} A (read back)"

    @property
    def busy(self) -> bool:
        """Steps to write, one under way, or a ramp's read-back still to come."""
        with self._condition:
            return bool(self._jobs) or self._working or self._settled_at is not None

    # --- a fault ------------------------------------------------------------------------------
    def make_safe(self, step_index: int) -> list[str]:
        """Drop what waits, ramp to zero from the last current accepted within the slew limit in
        host time, switch off and read back (stamped ``step_index``); what went wrong (a failure
        of the supply not yet taken by :meth:`failure` first), waiting
        for it while the supply answers, and no longer than the deadline of an exchange that hangs."""
        done = threading.Event()
        problems: list[str] = []

        def safe() -> None:
            try:
                for _, current_a in self.supply.config.limits.ramp(self.current_a, 0.0):
                    self.supply.set_current_a(current_a)
                    self.current_a = current_a
                    time.sleep(RAMP_STEP_S)
            except SupplyError as error:
                problems.append(f"THE SUPPLY DID NOT RAMP TO ZERO: {error}")
            try:
                problems.extend(f"THE SUPPLY MAY STILL BE ON: {p}" for p in self.supply.safe())
                self.current_a, self.off = 0.0, True
                self._read_back(step_index)
            except SupplyError as error:
                problems.append(f"THE SUPPLY MAY STILL BE ON: not read back: {error}")
            finally:
                done.set()

        with self._condition:
            untold = [self._failure] if self._failure else []  # told with the fault, not dropped
            self._jobs.clear()
            self._settled_at, self._watch_at_s, self._failure = None, math.inf, ""
            self._jobs.append(safe)
            self._safe_job = safe  # kept when a failure of the exchange under way drops the rest
            self._condition.notify()
        if not self._wait(done.is_set):
            return [*untold, f"THE SUPPLY MAY STILL BE ON: it did not answer within {self.deadline_s:g} s"]
        return untold + problems

    def close(self) -> None:
        """Stop the worker once its jobs are done, then close the supply (zero, every output off
        and read back, local control: :meth:`ScpiSupply.close`). SupplyError when the worker
        hung or the supply failed to close."""
        with self._condition:
            self._stopping = True
            self._condition.notify()
        if not self._wait(lambda: not self._thread.is_alive()):
            raise SupplyError(f"THE SUPPLY MAY STILL BE ON: it did not answer within {self.deadline_s:g} s")
        self.supply.close()

    # --- the worker ---------------------------------------------------------------------------
    def _queue(self, job: Callable[[], None]) -> None:
        with self._condition:
            self._jobs.append(job)
            self._condition.notify()

    def _run(self) -> None:
        self._started()
        while True:
            with self._condition:
                job = self._next_job()
                while job is None and not (self._stopping and not self._jobs):
                    self._condition.wait(self._wait_s())
                    job = self._next_job()
                if job is None:
                    return
                self._working = True
            try:
                job()
            except Exception as error:  # noqa: BLE001 (the line never dies on a step: a fault, said)
                with self._condition:
                    self._failure = self._failure or f"the supply failed: {error}"
                    kept = [j for j in self._jobs if j is self._safe_job]
                    self._jobs.clear()
                    self._jobs.extend(kept)
                    self._settled_at, self._watch_at_s = None, math.inf
            finally:
                with self._condition:
                    self._working = False

    def _next_job(self) -> Callable[[], None] | None:
        now = time.monotonic()
        if self._jobs:
            return self._jobs.popleft()
        if self._settled_at is not None and now >= self._settled_at[0]:
            step, self._settled_at = self._settled_at[1], None
            return lambda: self._read_back(step, watch=True)
        if now >= self._watch_at_s:
            return lambda: self._read_back(self._step_index, watch=True)
        return None

    def _wait_s(self) -> float | None:
        due = min(self._watch_at_s, self._settled_at[0] if self._settled_at else math.inf)
        return None if due == math.inf else max(0.0, due - time.monotonic())

    def _write_step(self, current_a: float, index: int, last: bool) -> None:
        if self.off:
            self.supply.prepare()  # at zero, output on, as when it was opened
            self.off = False
        # The slew limit holds in the supply's time: steps that waited (a busy host) are paced
        # one per RAMP_STEP_S, never written as a burst.
        time.sleep(max(0.0, self._stepped_s + RAMP_STEP_S - time.monotonic()))
        self._stepped_s = time.monotonic()
        self.supply.set_current_a(current_a)
        self.current_a, self._step_index = current_a, index
        with self._condition:
            # The pair settles in the supply's own time from the write, not on the card's clock.
            self._settled_at = (time.monotonic() + self.supply.config.settle_s, index) if last else None
            self._watch_at_s = math.inf

    def _switch_off(self) -> None:
        self.off = True
        refused = self.supply.safe()
        if refused:
            raise SupplyError(f"it did not switch off after the emergency stop: {'; '.join(refused)}")
        self._read_back(self._step_index)

    def _read_back(self, step_index: int, watch: bool = False) -> None:
        """Read the current and the output back; while the output should be on, an output read
        back off (it tripped) is a failure, and the next look is in ``WATCH_S``."""
        current_a = self.supply.read_current_a()
        output = self.supply.output_state()
        self.readback = Readback(current_a, output, step_index, time.monotonic())
        if watch and not self.off and output == "off":
            self.off = True
            tripped = " (its over-voltage protection tripped)" if self.supply.tripped() else ""
            raise SupplyError(f"its output went off by itself{tripped}")
        with self._condition:
            self._watch_at_s = time.monotonic() + WATCH_S if watch and not self.off else math.inf
