"""The exit statuses of every ``mows`` command (docs/cli.md), and what counts as Ctrl-C.

Standard library only: the command's entry point imports it before anything slow loads, so
that Ctrl-C while the command starts is one line and status 130 too.
"""

EXIT_OK = 0
EXIT_BUG = 1
EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command ended by Ctrl-C


def caused_by_interrupt(error: BaseException | None) -> bool:
    """Whether Ctrl-C is behind ``error``: an extension module interrupted while it loads (scipy's,
    on a slow start) turns the KeyboardInterrupt into ``ImportError: initialization failed``."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return True
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return False
