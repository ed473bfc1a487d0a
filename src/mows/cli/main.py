"""The ``mows`` command.

Each subcommand lives in the module of its job and exposes ``add_arguments(parser)`` and
``run(args) -> int``; this file only routes. Modules are imported lazily so that
``mows lab`` does not pay for the simulator's compilation, and the reverse.
"""
import argparse
import importlib
import sys

SUBCOMMANDS = {
    "sim": ("mows.cli.sim", "simulate measurement cycles from a scenario"),
    "fit": ("mows.cli.fit", "fit the ring-downs of a recorded bag (--csv: a model-lab table)"),
    "lab": ("mows.cli.lab", "compare the frequency model with measurements, find missing effects"),
    "bench": ("mows.cli.bench", "benchmarks: estimator, simulator, stream, lab (figures, never a failure)"),
    "calibrate": ("mows.cli.calibrate", "calibrate a new probe from a supply sweep (TABLE or --simulate)"),
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="mows", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    requested = (argv if argv is not None else sys.argv[1:])[:1]
    for name, (module_name, help_text) in SUBCOMMANDS.items():
        sp = sub.add_parser(name, help=help_text)
        if name in requested:
            module = importlib.import_module(module_name)
            module.add_arguments(sp)
            sp.set_defaults(_run=module.run)
    args = parser.parse_args(argv)
    return args._run(args)


if __name__ == "__main__":
    sys.exit(main())
