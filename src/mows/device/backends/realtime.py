"""The bench's host threads under real-time scheduling: the thread that polls the NI card (the
driver's stream thread), the supply's thread and the watchdog run under SCHED_FIFO at the device
file's ``realtime_priority``, so that busy processes beside the driver (a robot stack's, CPU
burners) cannot stall them beyond the card's output lead.

Where the system refuses (no root, no ``CAP_SYS_NICE``, an ``RLIMIT_RTPRIO`` below the priority;
not Linux), a thread stays at the default policy and the refusal is kept (:class:`Priority`
``refused``: the backend's stats say it): the bench then survives the stalls of its output lead
only, as before. A thread raised here is put back to its own policy when the backend closes, so
that a thread which polled a closed card does its other work at its own priority again.
"""

from __future__ import annotations

import dataclasses
import os
import threading

PARAM = getattr(os, "sched_param", None)  # not on every platform


@dataclasses.dataclass(frozen=True)
class Raised:
    """A thread raised to SCHED_FIFO: its native id and the policy and priority it had."""

    native_id: int
    policy: int
    priority: int


class Priority:
    """SCHED_FIFO at ``priority`` (1–99; 0: off) for the threads that ask, each put back by
    :meth:`restore`; ``refused``: why the system refused it ('' : it did not)."""

    def __init__(self, priority: int):
        self.priority = int(priority)
        self.refused = ""
        self._raised: dict[int, Raised] = {}
        self._lock = threading.Lock()

    def raise_thread(self) -> bool:
        """The calling thread under SCHED_FIFO at the priority (once per thread; one already under
        a real-time policy, the process's or another bench's, is left as it is); whether it is."""
        native_id = threading.get_native_id()
        with self._lock:
            if native_id in self._raised:
                return True
            if not self.priority or self.refused:
                return False
            if PARAM is None or not hasattr(os, "sched_setscheduler"):
                self.refused = "this system has no SCHED_FIFO"
                return False
            try:
                before = Raised(native_id, os.sched_getscheduler(0), os.sched_getparam(0).sched_priority)
                if before.policy in (os.SCHED_FIFO, os.SCHED_RR):  # real-time already: its owner's, left so
                    return True
                os.sched_setscheduler(0, os.SCHED_FIFO, PARAM(self.priority))
            except OSError as error:
                self.refused = (
                    f"SCHED_FIFO {self.priority} refused ({error.strerror}): needs root, CAP_SYS_NICE or RLIMIT_RTPRIO"
                )
                return False
            self._raised[native_id] = before
            return True

    def restore(self) -> None:
        """Every thread raised put back to its own policy (one that has ended is left)."""
        with self._lock:
            raised, self._raised = list(self._raised.values()), {}
        for thread in raised:
            try:
                os.sched_setscheduler(thread.native_id, thread.policy, PARAM(thread.priority))  # type: ignore[misc]
            except OSError:  # the thread has ended
                pass

    @property
    def state(self) -> str:
        """For the stats: 'SCHED_FIFO N', 'off' or why it was refused."""
        if self.refused:
            return self.refused
        return f"SCHED_FIFO {self.priority}" if self.priority else "off"
