"""The exit statuses of every ``mows`` command (docs/cli.md), and what counts as Ctrl-C or SIGTERM.

Standard library only: the command's entry point imports it before anything slow loads, so
that Ctrl-C while the command starts is one line and status 130 too.
"""

import signal

EXIT_OK = 0
EXIT_BUG = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command ended by Ctrl-C
EXIT_TERMINATED = 143  # 128 + SIGTERM
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE: stdout's reader left (``| head``), as a shell reports it


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is, so that it unwinds as from Ctrl-C: every output's
    temporaries removed, nothing half-written (:mod:`mows.records.files`)."""


def _terminate(_signum, _frame) -> None:
    raise Terminated


def stop_on_sigterm() -> None:
    """SIGTERM ends the command as Ctrl-C does (:class:`Terminated`), not on the spot."""
    signal.signal(signal.SIGTERM, _terminate)


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
    """The one line and the exit status of a command ended by Ctrl-C or SIGTERM."""
    if isinstance(interrupt_behind(error), Terminated):
        return f"{prog}: terminated", EXIT_TERMINATED
    return f"{prog}: interrupted", EXIT_INTERRUPTED
