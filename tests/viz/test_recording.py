"""A recording's derived MCAP (``mows viz BAG``) read back with the ``mcap`` reader: the schemas
Foxglove needs on every channel, the messages readable by them, and the layout's topics all there."""

import json
from pathlib import Path

from mcap.reader import make_reader

from foxglove_protobuf import decode, descriptors
from mows.cli.main import main
from viz.session import recorded_session

LAYOUT = Path("mows_viz/config/mows.foxglove.json")
MOUNT = "mows_bringup/urdf/mows_probe_mount.urdf"


def test_mows_viz_writes_the_channels_foxglove_opens(tmp_path, capsys):
    bag, fits = recorded_session(tmp_path)
    assert main(["viz", str(bag), "--mount", MOUNT]) == 0
    output = bag.parent / f"{bag.name}.view.mcap"
    assert f"wrote {output}" in capsys.readouterr().out
    with open(output, "rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        schemas = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
        encodings = {c.topic: c.message_encoding for c in summary.channels.values()}
        messages = {}
        for schema, channel, message in reader.iter_messages():
            messages.setdefault(channel.topic, []).append((schema, message))
    assert (schemas["/mows/viz/scene"].name, schemas["/mows/viz/scene"].encoding) == (
        "foxglove.SceneUpdate",
        "protobuf",
    )
    assert (schemas["/mows/viz/frames"].name, encodings["/mows/viz/frames"]) == ("foxglove.FrameTransforms", "protobuf")
    for topic in ("/mows/viz/raw", "/mows/viz/ringdown", "/mows/viz/sweep", "/mows/viz/lab", "/mows/viz/diagnostics"):
        assert (schemas[topic].encoding, encodings[topic]) == ("jsonschema", "json"), topic
    scene_schema, scene = messages["/mows/viz/scene"][-1]
    update = decode(scene.data, scene_schema.name, descriptors(scene_schema.data))
    assert update["entities"][0]["arrows"] and update["entities"][0]["texts"]
    ringdowns = [json.loads(m.data) for _, m in messages["/mows/viz/ringdown"]]
    assert [r["frequency_hz"] for r in ringdowns] == [f.frequency_hz for f in fits]
    # Every topic the layout's panels name is in the file.
    layout = LAYOUT.read_text()
    named = {topic for topic in schemas if topic in layout}
    assert named == set(schemas), sorted(set(schemas) - named)
    assert main(["viz", str(bag), "--mount", MOUNT]) == 2  # never over an existing file without --force


def test_the_layouts_xy_plots_show_the_latest_message():
    # "custom" accumulates every message's arrays: each ring-down would be drawn over the last.
    panels = json.loads(LAYOUT.read_text())["configById"]
    xy = {name: panel for name, panel in panels.items() if name.startswith("Plot!") and "xAxisPath" in panel}
    assert set(xy) == {"Plot!ringdown", "Plot!sweep", "Plot!sweep_points", "Plot!lab"}
    assert {name: panel["xAxisVal"] for name, panel in xy.items()} == dict.fromkeys(xy, "currentCustom")
