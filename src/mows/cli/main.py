"""The ``mows`` command.

Each subcommand lives in the module of its job and exposes ``add_arguments(parser)`` and
``run(args) -> int``; this file only routes. Modules are imported lazily so that
``mows lab`` does not pay for the simulator's compilation, and the reverse. Errors take one
path (:mod:`mows.cli.inputs`): a bad input is one line and exit status 2, ``--debug`` (before
or after the subcommand) shows the traceback. At import this file loads the standard library
alone (and :mod:`mows.cli.status`): Ctrl-C while numpy or scipy load is then inside
:func:`main`, one line and status 130.
"""

import argparse
import atexit
import contextlib
import functools
import importlib
import os
import sys

from mows.cli.status import caused_by_interrupt, interrupted, settle, stop_on_signals

SUBCOMMANDS = {
    "sim": ("mows.cli.sim", "simulate measurement cycles from a scenario"),
    "fit": ("mows.cli.fit_bag", "fit the ring-downs of a recorded bag (--csv: a model-lab table)"),
    "map": ("mows.cli.map_bag", "the field map of a recorded session, made again offline as the mapper made it"),
    "bag": ("mows.cli.bag", "repair a recording that was never closed (killed): rebuild it from its intact chunks"),
    "lab": ("mows.cli.lab", "compare the frequency model with measurements, find missing effects"),
    "bench": ("mows.cli.bench", "benchmarks: estimator, simulator, stream, lab (figures, never a failure)"),
    "calibrate": ("mows.cli.calibrate", "calibrate a new probe from a supply sweep (BAG, TABLE or --simulate)"),
    "viz": ("mows.cli.viz", "a recorded bag's view for Foxglove: scene, model curves and plots in an MCAP file"),
    "check-hardware": ("mows.cli.check_hardware", "check the NI card, the coils and the SCPI supply step by step"),
}


EPILOG = """exit status: 0 done; 1 a bug (one line; --debug for the traceback); 2 a bad input or
usage (one line naming the file, key or option); 130 interrupted (Ctrl-C); 143 terminated
(SIGTERM). Outputs appear whole
or not at all, never over an input, over an existing file only with --force (docs/cli.md)."""


def main(argv=None) -> int:
    words = sys.argv[1:] if argv is None else list(argv)
    if argv is None:  # the command itself, not a caller's test
        stop_on_signals()
    prog = _prog(words)
    try:
        status = _main(words)
    # Ctrl-C while the subcommand's modules load (within it, report_errors says it)
    except (KeyboardInterrupt, ImportError) as error:
        if "--debug" in words or not caused_by_interrupt(error):
            raise
        line, status = interrupted(prog, error)
        print(line, file=sys.stderr)
    if argv is not None:
        return status
    status = settle(prog, status)
    # Out now: a signal during the interpreter's own shutdown (its handlers restored to the
    # default) would end the process without a word, after the status was decided.
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError):  # a reader that left has been told nothing more
            stream.flush()
    os._exit(status)


def _prog(words: list) -> str:
    """``mows`` and its subcommand as its errors name it (``mows lab report``)."""
    named = [word for word in words if not word.startswith("-")]
    return (
        " ".join(["mows", *named[: 2 if named[:1] == ["lab"] else 1]])
        if named[:1] and named[0] in SUBCOMMANDS
        else "mows"
    )


def _main(argv: list) -> int:
    from mows.cli.inputs import OneLineParser, UsageError, report_errors  # numpy: within main's Ctrl-C
    from mows.records.files import command_inputs

    parser = OneLineParser(
        prog="mows",
        description=__doc__.splitlines()[0],
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True)
    requested = [word for word in argv if not word.startswith("-")][:1]
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        sp = sub.add_parser(name, help=help_text)
        if name in requested:
            module = importlib.import_module(module_name)
            module.add_arguments(sp)
            sp.set_defaults(_run=module.run)
        _add_debug(sp)
    try:
        args, unknown = parser.parse_known_args(argv)
        if unknown:  # the subcommand's parser says it, with its own name and --help
            _chosen(parser, args).error(f"unrecognized arguments: {' '.join(unknown)}")
    except UsageError as error:  # the one line and the status of every bad input
        return report_errors(error.prog, functools.partial(_refuse, error), "--debug" in argv)
    with command_inputs():  # every file the command reads is an input, not only its arguments
        return report_errors(_chosen(parser, args).prog, lambda: args._run(args), args.debug)


def _chosen(parser: argparse.ArgumentParser, args: argparse.Namespace) -> argparse.ArgumentParser:
    """The innermost (sub)command parser that ``args`` went through: ``mows lab report``'s."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction) and getattr(args, action.dest, None) in action.choices:
            return _chosen(action.choices[getattr(args, action.dest)], args)
    return parser


def _refuse(error: ValueError) -> int:
    raise error


def _add_debug(parser: argparse.ArgumentParser) -> None:
    """``--debug`` also after the subcommand (and after ``mows lab``'s own subcommands)."""
    parser.add_argument(
        "--debug", action="store_true", default=argparse.SUPPRESS, help="show the traceback of an error"
    )
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for subparser in action.choices.values():
                _add_debug(subparser)


if __name__ == "__main__":
    sys.exit(main())
