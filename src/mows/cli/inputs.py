"""One error path for every ``mows`` command.

A bad input (a table, a bag, a probe or scenario file, a plugin, an argument) ends the
command with one line on stderr that names the file, the row or key and what is allowed, and
exit status 2 (a command line the parser refuses too: :class:`OneLineParser`); ``--debug``
shows the traceback instead. Ctrl-C is one line and exit status 130 (docs/cli.md).
Our YAML files (probe files, scenarios, the bench's device and supply files) name themselves in
their refusals (:func:`mows.physics.schema.load_yaml`); :func:`input_file` blames what goes
wrong while any other file is read on that file, in words (a directory, not UTF-8, not YAML);
:func:`report_errors` turns the errors into the line and the status. Anything else is a bug:
exit status 1, one line, and the traceback with ``--debug``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import pathlib
import sys
import traceback
import warnings
from collections.abc import Callable, Iterator
from typing import NoReturn

import numpy as np
import yaml

from mows.cli.status import (
    EXIT_BAD_INPUT,
    EXIT_BROKEN_PIPE,
    EXIT_BUG,
    EXIT_OK,
    caused_by_interrupt,
    interrupted,
    raised_by_a_signal,
    signalled,
)
from mows.physics import ranges
from mows.physics.schema import unreadable, yaml_problem
from mows.records.files import read_input

#: Exceptions that mean "the input is bad". ValueError covers the library's own refusals
#: (TableError, OutputRefused, a scenario's out-of-range value) and UnicodeDecodeError.
INPUT_ERRORS = (ValueError, OSError, KeyError, yaml.YAMLError)


class InputError(ValueError):
    """A bad input whose message already names the file."""


def one_line(error: BaseException) -> str:
    """The error's message on one line (YAML errors and some numpy ones span several)."""
    if isinstance(error, KeyError) and len(error.args) == 1:
        return f"missing key {error.args[0]!r}"
    if isinstance(error, yaml.YAMLError):
        return yaml_problem(error)
    return " ".join(str(error).split()) or type(error).__name__


@contextlib.contextmanager
def input_file(path, what: str = "") -> Iterator[pathlib.Path]:
    """Read ``path`` inside the ``with`` block; what goes wrong is reported as this file's fault
    (:class:`InputError` with ``what`` and the file's name), unless the message already names it."""
    path = read_input(path)
    name = f"{what} {path}" if what else str(path)
    try:
        yield path
    except InputError:
        raise
    except (OSError, UnicodeDecodeError) as error:
        raise InputError(unreadable(name, error)) from None
    except (ValueError, KeyError, yaml.YAMLError) as error:
        message = one_line(error)
        raise InputError(message if str(path) in message else f"{name}: {message}") from error


class UsageError(ValueError):
    """A command line the parser of ``prog`` refused: an unknown option, a value out of range."""

    def __init__(self, prog: str, message: str):
        super().__init__(message)
        self.prog = prog


class OneLineParser(argparse.ArgumentParser):
    """An argument parser whose refusal is :class:`UsageError` (one line, exit status 2, by
    :func:`report_errors`), not argparse's usage block and ``SystemExit``."""

    def error(self, message):
        raise UsageError(self.prog, f"{message} (see {self.prog} --help)")


def renamed_option(parser: argparse.ArgumentParser, old: str, new: str) -> None:
    """``old`` stays known for one release only to be refused with the name that replaced it."""

    class Renamed(argparse.Action):
        def __call__(self, parser, namespace, values, option_string=None):
            parser.error(f"{old} is renamed {new}: give {new}")

    parser.add_argument(old, action=Renamed, help=argparse.SUPPRESS)


def finite_float(text: str) -> float:
    """An argparse type: a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not np.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text} must be a finite number")
    return value


def non_negative_float(text: str) -> float:
    """An argparse type: a finite number ≥ 0 (a duration)."""
    value = finite_float(text)
    if value < 0.0:
        raise argparse.ArgumentTypeError(f"{value:g} must be ≥ 0")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a finite number > 0 (a frequency, a count of periods)."""
    value = finite_float(text)
    if value <= 0.0:
        raise argparse.ArgumentTypeError(f"{value:g} must be > 0")
    return value


def sensor_length_m(text: str) -> float:
    """An argparse type: a length of the sensor geometry, m, > 0 and in its range (:mod:`mows.physics.ranges`)."""
    if finite_float(text) <= 0.0:
        raise argparse.ArgumentTypeError(f"{text} m: a sensor length is > 0")
    return _ranged("sensor_length_m", text)


def magnet_position_m(text: str) -> float:
    """An argparse type: a coordinate of the magnet's position, m, in its range."""
    return _ranged("magnet_position_m", text)


def _ranged(quantity: str, text: str) -> float:
    try:
        return ranges.check(quantity, finite_float(text), "the value", warn=False)  # parsed before warnings are kept
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def positive_int(text: str) -> int:
    """An argparse type: an integer ≥ 1 (a count of repeats, cycles, ring-downs)."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} must be at least 1")
    return value


def report_errors(prog: str, work: Callable[[], int], debug: bool = False) -> int:
    """``work()``'s exit status; a bad input → one line and 2, a bug → one line and 1, Ctrl-C
    → one line and 130, SIGTERM 143 (outputs are only renamed into place once complete, so none
    is left). Warnings raised on the way (numpy's, over values a check then refuses) never come
    before that line: a command that ends in an error says only the error; one that succeeds
    says each distinct warning once, on a line of its own. ``debug`` shows everything as raised."""
    if debug:
        return _status(prog, work, debug)
    with warnings.catch_warnings(record=True) as caught:
        status = _status(prog, work, debug)
    if status == EXIT_OK:
        for text in dict.fromkeys(" ".join(str(w.message).split()) for w in caught):
            print(f"{prog}: warning: {text}", file=sys.stderr)
    return status


class ExitCalled(SystemExit):
    """``os._exit`` called in the command's own process while it works (:func:`_exits_refused`)."""


@contextlib.contextmanager
def _exits_refused() -> Iterator[None]:
    """Within the block ``os._exit`` in this process raises :class:`ExitCalled` instead of ending
    it unseen (a plugin's, say); a forked child (another process id) still exits by it."""
    owner, exit_now = os.getpid(), os._exit

    def refuse(status: int) -> NoReturn:
        if os.getpid() != owner:
            exit_now(status)
        raise ExitCalled(status)

    os._exit = refuse
    try:
        yield
    finally:
        os._exit = exit_now


def _exit_site(error: BaseException) -> str:
    """Where ``error`` was raised: the file and line of its innermost frame (of its caller's, for
    :class:`ExitCalled`, whose innermost frame is the refusal's)."""
    frames = list(traceback.extract_tb(error.__traceback__))[: -1 if isinstance(error, ExitCalled) else None]
    return f"{frames[-1].filename}:{frames[-1].lineno}" if frames else "the command"


def _refuse_exit(prog: str, error: SystemExit | KeyboardInterrupt) -> int:
    """The line and the status of code (a plugin's) that tried to end the command."""
    if isinstance(error, KeyboardInterrupt):
        how = "raise KeyboardInterrupt, without a signal"
    else:
        how = f"{'os._exit' if isinstance(error, ExitCalled) else 'sys.exit'}({error.code!r})"
    print(
        f"{prog}: error: {_exit_site(error)} tried to end the command ({how}): "
        "a plugin must return or raise, never exit",
        file=sys.stderr,
    )
    return EXIT_BAD_INPUT


def _status(prog: str, work: Callable[[], int], debug: bool) -> int:
    """:func:`report_errors` without the warnings."""
    try:
        with _exits_refused():
            return work()
    except KeyboardInterrupt as error:
        if debug:
            raise
        if not raised_by_a_signal():  # raised by code (a plugin's), not by Ctrl-C or SIGTERM
            return _refuse_exit(prog, error)
        line, status = interrupted(prog, error)
        print(line, file=sys.stderr)
        return status
    except SystemExit as error:  # our commands return their status: this came from a plugin or library
        if debug:
            raise
        return _refuse_exit(prog, error)
    except BrokenPipeError:
        # The reader of stdout left (``| head``): nothing is wrong, and nothing more can be said
        # there; Python's own flush at exit would fail again, so stdout goes to /dev/null.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except INPUT_ERRORS as error:
        if debug:
            raise
        if not signalled():
            print(f"{prog}: error: {one_line(error)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as error:  # noqa: BLE001 - the one place a bug is turned into a line
        if debug:
            raise
        if caused_by_interrupt(error):
            line, status = interrupted(prog, error)
            print(line, file=sys.stderr)
            return status
        if signalled():
            return EXIT_BUG
        print(
            f"{prog}: internal error: {type(error).__name__}: {one_line(error)} "
            "(a bug: rerun with --debug for the traceback and report it)",
            file=sys.stderr,
        )
        return EXIT_BUG
