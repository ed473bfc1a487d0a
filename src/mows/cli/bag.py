"""``mows bag repair DIR``: rebuild a recording that was never closed from its intact chunks.

A driver killed with SIGKILL (or a power cut) leaves a bag whose MCAP file has no summary and
whose ``metadata.yaml`` still says it is open: readers refuse it. ``repair`` keeps every whole
chunk (:mod:`mows.device.recording.bag_repair`), writes a closed MCAP and a complete ``metadata.yaml``
in the bag directory, keeps the damaged file as ``NAME.mcap.damaged`` and prints how many
messages were recovered and what was lost. A bag that reads already is left alone (exit 2).
"""

import argparse

from mows.device.recording.bag_repair import repair


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="bag_command", required=True)
    command = sub.add_parser(
        "repair", help="rebuild a killed recording from its intact chunks", description=__doc__.splitlines()[0]
    )
    command.add_argument("bag", help="the bag directory (the driver's record_path)")


def run(args) -> int:
    found = repair(args.bag)
    print(found.summary())
    print(f"repaired {args.bag}: {len(found.messages)} messages; the damaged file is kept beside it (.damaged)")
    return 0
