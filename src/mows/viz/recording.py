"""A recorded session's derived channels in an MCAP file (``mows viz BAG``): the driver's bag
(``record_path``: the stream, the excitation, the joint states and what the graph concluded)
read in time order through a :class:`mows.viz.view.View`, and each channel's messages written
with the ``mcap`` writer, log-timed as the bag's (the raw stream at its samples' device time).
Foxglove opens the bag and this file together, with the layout of the live view.
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path

from mcap.writer import Writer

from mows.device.recording.bags import read_bag
from mows.viz import channels
from mows.viz.view import Shown, View

# The graph's topics a View takes, and how.
FEEDS: dict[str, Callable[[View, object, int], list[Shown]]] = {
    "/mows/raw": lambda view, msg, _: view.on_raw(msg),
    "/mows/ringdown": View.on_ringdown,
    "/mows/field": View.on_field,
    "/mows/sweep": View.on_sweep,
    "/mows/field_map": View.on_field_map,
    "/mows/model_report": View.on_model_report,
    "/mows/workspace_model": View.on_workspace_model,
    "/mows/excitation": View.on_excitation,
    "/mows/joint_states": View.on_joint_states,
    "/diagnostics": View.on_diagnostics,
}


class McapChannels:
    """An open MCAP writer and its channels, registered as their first message comes."""

    def __init__(self, stream):
        self._writer = Writer(stream)
        self._writer.start(profile="", library="mows viz")
        self._ids: dict[str, int] = {}
        self.counts: Counter = Counter()

    def write(self, shown: Shown) -> None:
        if shown.topic not in self._ids:
            found = channels.schema(shown.topic)
            schema_id = self._writer.register_schema(found.name, found.encoding, found.data)
            self._ids[shown.topic] = self._writer.register_channel(shown.topic, found.message_encoding, schema_id)
        time_ns = int(shown.log_time_ns)
        self._writer.add_message(self._ids[shown.topic], time_ns, channels.payload(shown), time_ns)
        self.counts[shown.topic] += 1

    def finish(self) -> None:
        self._writer.finish()


def view_messages(bag: str | os.PathLike, view: View) -> Iterable[Shown]:
    """What ``view`` shows of the bag's messages, in the bag's order."""
    for record in read_bag(bag, FEEDS):
        yield from FEEDS[record.topic](view, record.message, record.timestamp_ns)


def write_view(bag: str | os.PathLike, output: Path, view: View) -> Counter:
    """The derived channels of ``bag`` into the MCAP file ``output`` (opened here); messages per topic."""
    with open(output, "wb") as stream:
        written = McapChannels(stream)
        for shown in view_messages(bag, view):
            written.write(shown)
        written.finish()
    return written.counts


def default_output(bag: str | os.PathLike) -> Path:
    """Next to the recording: ``<bag>.view.mcap`` beside the bag's directory (or beside the
    ``.mcap`` file of a bag named by it, outside its folder, which is never written in)."""
    path = Path(bag)
    if path.is_file() and (path.parent / "metadata.yaml").is_file():
        path = path.parent if path.parent.name else path.resolve().parent
    return path.parent / f"{path.name}.view.mcap"
