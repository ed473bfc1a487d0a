"""``mows viz BAG [-o VIEW.mcap | --figures DIR]``: a recorded session's derived channels for Foxglove.

Reads the driver's bag (``record_path``) and writes what the live view (the ``mows_viz`` node,
``mows-graph --foxglove``) shows of it into one MCAP file, next to the recording by default
(``BAG.view.mcap``): the probes' arrows, the mount's frames (``--mount``: the probe mount's
URDF), the raw stream, each ring-down with its model and residual, the sweeps, the lab's error
history, the excitation and /diagnostics (:mod:`mows.viz`). Open the bag and this file together
in Foxglove with mows_viz/config/mows.foxglove.json (docs/visualisation.md).

``--figures DIR`` draws each panel's content instead, one PNG per panel in DIR (``scene.png``,
``ringdown.png``, ``sweep.png``, ``lab.png``, ``excitation.png``; :mod:`mows.viz.figures`).
"""

import argparse
from pathlib import Path

from mows.viz.mount import Mount
from mows.viz.recording import default_output, write_view
from mows.viz.view import View, ViewSettings


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = __doc__.splitlines()[0]
    parser.add_argument("bag", help="the recorded bag directory (the driver's record_path)")
    written = parser.add_mutually_exclusive_group()
    written.add_argument("-o", "--output", type=Path, help="the MCAP file to write (default: BAG.view.mcap beside it)")
    parser.add_argument("--mount", type=Path, help="the probe mount's URDF, for its frames (default: no frames)")
    parser.add_argument(
        "--channels",
        default="difference",
        choices=("difference", "channel1", "channel2"),
        help="what the estimator fitted (its channels parameter; default difference)",
    )
    parser.add_argument("--coil-current-cap-a", type=float, default=10.0, help="the driver's coil_current_cap_a (A)")
    written.add_argument(
        "--figures",
        type=Path,
        metavar="DIR",
        help="draw each panel's content as a PNG in DIR instead of writing the MCAP file",
    )
    parser.add_argument("--force", action="store_true", help="replace an existing output file")


def run(args) -> int:
    from mows.cli.inputs import input_file
    from mows.records.files import writing

    mount = None
    if args.mount is not None:
        with input_file(args.mount, "mount") as path:
            mount = Mount(path.read_text())
    view = View(ViewSettings(channels=args.channels, coil_current_cap_a=args.coil_current_cap_a), mount)
    if args.figures is not None:
        return write_figures(args, view)
    output = args.output or default_output(args.bag)
    with writing([output], _inputs(args), args.force) as outputs:
        counts = write_view(args.bag, outputs.temporaries[0], view)
    print(outputs.report())
    for topic, count in sorted(counts.items()):
        print(f"  {topic}: {count} messages")
    return 0


def write_figures(args, view: View) -> int:
    """Each panel the session has, as ``DIR/<panel>.png``."""
    from mows.records.files import check_not_input, writing
    from mows.viz.figures import Panels, draw
    from mows.viz.recording import view_messages

    check_not_input(args.figures / "scene.png", _inputs(args))  # before the folder is made
    panels = Panels.of(view_messages(args.bag, view))
    names = panels.names()
    args.figures.mkdir(parents=True, exist_ok=True)
    with writing([args.figures / f"{name}.png" for name in names], _inputs(args), args.force) as outputs:
        for name, temporary in zip(names, outputs.temporaries):
            temporary.write_bytes(draw(panels, name).png)
    print(outputs.report())
    return 0


def _inputs(args) -> list:
    return [args.bag] + ([args.mount] if args.mount is not None else [])
