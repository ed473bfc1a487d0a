"""The exit statuses of every ``mows`` command (docs/cli.md), and what counts as Ctrl-C or SIGTERM.

Standard library only: the command's entry point imports it before anything slow loads, so
that Ctrl-C while the command starts is one line and status 130 too.
"""

import contextlib
import os
import signal
import sys
import threading
import time

EXIT_OK = 0
EXIT_BUG = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command ended by Ctrl-C
EXIT_TERMINATED = 143  # 128 + SIGTERM
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: stdout's reader left (``| head``), as a shell reports it


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is, so that it unwinds as from Ctrl-C: every output's
    temporaries removed, nothing half-written (:mod:`mows.records.files`)."""


# Signals always win. The handler raises the interrupt where the command is (so that it unwinds
# through every clean-up); but Python discards an exception raised inside a weakref callback or
# a __del__ (it reaches sys.unraisablehook instead), so the hook has the signal sent again and
# the command's next bytecode gets it. Each signal is also written by the C-level handler to a
# pipe (signal.set_wakeup_fd), which the command's last step reads: a signal whose exception was
# swallowed anyway, or that came while the interpreter was about to exit, still decides the
# status and the line.
_received: list[int] = []  # the signals the handler has seen, in order
_raised = False  # an interrupt is on its way up the stack: a second signal does not cut its clean-up
_wakeup: int | None = None  # the read end of the pipe the C handler writes signal numbers to
_handling = False  # this process's SIGINT and SIGTERM come to _on_signal (the command itself runs)
# _unraisable is at work: a signal now is only noted. A plain flag: its last store in the hook
# runs no code after it in which the signal sent again could be handled (within the hook).
_in_hook = False
# The interrupts that ended the command's work, kept until the process ends (os._exit frees
# nothing): their frames hold what the signal cut short, such as numba's half-loaded kernels,
# whose C objects may be freed twice if taken apart (a segmentation fault after the line).
_cut_short: list[BaseException] = []
_EXCEPTIONS: dict[int, type[KeyboardInterrupt]] = {signal.SIGINT: KeyboardInterrupt, signal.SIGTERM: Terminated}
EXIT_OF: dict[int, int] = {signal.SIGINT: EXIT_INTERRUPTED, signal.SIGTERM: EXIT_TERMINATED}


def _on_signal(signum, _frame) -> None:
    global _raised
    _received.append(signum)
    if not _raised and not _in_hook:  # raised in the hook, it would be discarded again
        _raised = True
        raise _EXCEPTIONS[_received[0]]


def _unraisable(unraisable, default=sys.unraisablehook) -> None:
    """An interrupt Python discarded (raised in a weakref callback, a __del__): sent again, from
    another thread once this hook has returned (starting that thread waits for it, and a signal
    that came meanwhile would be raised, and discarded, here)."""
    global _raised, _in_hook
    if isinstance(unraisable.exc_value, KeyboardInterrupt) and _received:
        _raised = False
        _in_hook = True
        try:
            threading.Thread(target=_send_again, args=(_received[0],), daemon=True).start()
        finally:
            _in_hook = False
        return
    if _received:
        # The command is ending on a signal (its line said or about to be): an error in the
        # clean-up of work the signal cut short (a __del__ of numba's compiler, interrupted while
        # it compiled on a first run) is that interruption's debris, not a second story.
        return
    default(unraisable)


def _send_again(signum: int) -> None:
    while _in_hook:
        time.sleep(0.001)
    os.kill(os.getpid(), signum)


def stop_on_signals() -> None:
    """SIGINT and SIGTERM end the command with one line and status 130 or 143, whenever they
    come (a SIGINT ignored by whoever started us, as for a background job, stays ignored)."""
    global _wakeup, _handling
    read, write = os.pipe()
    os.set_blocking(read, False)
    os.set_blocking(write, False)
    signal.set_wakeup_fd(write, warn_on_full_buffer=False)
    _wakeup = read
    for signum in _EXCEPTIONS:
        if signal.getsignal(signum) is not signal.SIG_IGN:
            signal.signal(signum, _on_signal)
    sys.unraisablehook = _unraisable
    _handling = True


def raised_by_a_signal() -> bool:
    """Whether a KeyboardInterrupt now on its way up came from a signal: where the command's own
    handlers are in place, only if they have seen one (otherwise code raised it); where they are
    not (a caller's ``main(argv)``), it may have, and is taken so."""
    return bool(_received) or not _handling


def signalled() -> bool:
    """Whether the command's own handlers have seen SIGINT or SIGTERM: an error raised after one
    is what it cut short (a library that swallows the interrupt and fails on its half-done
    state), and :func:`settle` says the signal instead."""
    return bool(_received)


def settle(prog: str, status: int) -> int:
    """The command's final status: from here on signals are ignored, and one that came at any
    time before (even one whose exception was swallowed) makes it 130 or 143, saying so in one
    line unless the command already did."""
    for signum in _EXCEPTIONS:
        if signal.getsignal(signum) is _on_signal:
            signal.signal(signum, signal.SIG_IGN)
    received = list(_received)
    if _wakeup is not None:
        with contextlib.suppress(BlockingIOError):
            received += [byte for byte in os.read(_wakeup, 64) if byte in EXIT_OF]
    if not received or status in EXIT_OF.values():
        return status
    line, status = interrupted(prog, _EXCEPTIONS[received[0]]())
    print(line, file=sys.stderr)
    return status


def interrupt_behind(error: BaseException | None) -> KeyboardInterrupt | None:
    """The Ctrl-C (or SIGTERM) behind ``error``: an extension module interrupted while it loads
    (scipy's, on a slow start) turns the KeyboardInterrupt into ``ImportError: initialization
    failed``."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None


def caused_by_interrupt(error: BaseException | None) -> bool:
    """Whether Ctrl-C or SIGTERM is behind ``error`` (:func:`interrupt_behind`)."""
    return interrupt_behind(error) is not None


def interrupted(prog: str, error: BaseException) -> tuple[str, int]:
    """The one line and the exit status of a command ended by Ctrl-C or SIGTERM (``error``, with
    the work it cut short, is kept whole until the command's process ends)."""
    if _handling:
        _cut_short.append(error)
    if isinstance(interrupt_behind(error), Terminated):
        return f"{prog}: terminated", EXIT_TERMINATED
    return f"{prog}: interrupted", EXIT_INTERRUPTED
