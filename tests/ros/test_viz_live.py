"""The graph live in Foxglove: ``mows-graph --foxglove`` on the simulator in tracking mode, a
client speaking Foxglove's WebSocket protocol (tests/foxglove_client.py), and the values it
receives checked against the graph's own topics: each ring-down's frequency on /mows/ringdown,
the field along the axis on /mows/field, and a sweep's field on /mows/sweep.
"""

import base64
import json
import math
import socket

import numpy as np
import pytest
from mows_msgs.msg import FieldEstimate, RingdownFit, SweepDecomposition

from foxglove_client import FoxgloveClient
from foxglove_protobuf import decode, descriptors
from mows.viz.scene import field_magnitude
from mows_ros.qos import MAP_QOS, RESULT_QOS
from node_processes import START_S, log

pytestmark = pytest.mark.ros

WANTED = ("/mows/viz/scene", "/mows/viz/ringdown", "/mows/viz/raw", "/mows/viz/frames")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def sweep_message() -> SweepDecomposition:
    msg = SweepDecomposition(sweep_id=7, status=0, model="first_principles", probe_id=0)
    msg.header.frame_id = "mows_rotation_plane"
    msg.field_t = [4.0e-5, -3.0e-5]
    msg.field_covariance_t2 = [1e-14, 0.0, 0.0, 4e-14]
    msg.gradient_t_per_m = [1e-4, 2e-5, -1e-4]
    msg.gradient_covariance = list(np.diag([1e-12, 1e-12, 1e-12]).ravel())
    msg.theta0_rad = [0.0, 1.0, 2.0, 3.0, 4.0]
    msg.frequency_shift_hz = [0.1, 0.2, 0.3, 0.2, 0.1]
    msg.frequency_shift_std_hz = [0.01] * 5
    msg.harmonic_amplitude_hz = [0.2, 0.1]
    msg.harmonic_phase_rad = [0.0, 0.0]
    return msg


def texts(scene_bytes: bytes, schema: dict) -> dict[str, list[str]]:
    """Each entity's labels, by entity id, of an encoded foxglove.SceneUpdate."""
    types = descriptors(base64.b64decode(schema["schema"]))
    update = decode(scene_bytes, schema["schemaName"], types)
    return {e["id"]: [t["text"] for t in e["texts"]] for e in update["entities"]}


def test_foxglove_client_sees_the_graph_s_values(ros, start):
    port = free_port()
    graph = start("mows-graph", f"--foxglove={port}", "--ros-args", "-p", "driver:tracking:=true")
    fits, fields = [], []
    ros.node.create_subscription(RingdownFit, "mows/ringdown", fits.append, RESULT_QOS)
    ros.node.create_subscription(FieldEstimate, "mows/field", fields.append, RESULT_QOS)
    client = FoxgloveClient(port, WANTED)
    try:
        ros.wait_for(
            lambda: f"ws://127.0.0.1:{port}" in log(graph) or graph.poll() is not None,
            "the viz node's address",
            START_S,
        )
        assert graph.poll() is None, log(graph)
        ros.wait_for(
            lambda: all(client.payloads(t) for t in WANTED[1:3]) or client.errors or graph.poll() is not None,
            "ring-downs and raw samples once the graph is up",
            START_S,
        )
        assert graph.poll() is None, log(graph)
        assert not client.errors, client.errors
        # The ring-down channel's plots are the graph's fits: the same frequency, cycle by cycle.
        heard = {(f.cycle_id, f.repeat_index): f for f in fits if f.status == 0}
        plots = [json.loads(m) for m in client.payloads("/mows/viz/ringdown")]
        ros.wait_for(
            lambda: all((p["cycle_id"], p["repeat_index"]) in heard for p in plots), "the fits on /mows/ringdown"
        )
        for plot in plots:
            fit = heard[(plot["cycle_id"], plot["repeat_index"])]
            assert plot["frequency_hz"] == fit.frequency_hz and plot["frequency_std_hz"] == fit.frequency_std_hz
            residual = np.array(plot["residual_t"], float)
            assert np.nanstd(residual) < 0.5 * np.nanstd(np.array(plot["data_t"], float))
        raw = json.loads(client.payloads("/mows/viz/raw")[-1])
        assert raw["difference_t"] == pytest.approx(raw["near_t"] - raw["far_t"])
        # The scene: the axis arrow of the latest field estimate, labelled with its value ± σ.
        scene = client.channel("/mows/viz/scene")
        assert (scene["encoding"], scene["schemaName"], scene["schemaEncoding"]) == (
            "protobuf", "foxglove.SceneUpdate", "protobuf",
        )  # fmt: skip

        # The latest scene may be of an estimate this test has not taken yet, or took before
        # its subscription matched: waited for until they agree (a wrong label never does).
        def axis_label() -> str | None:
            scenes = client.payloads("/mows/viz/scene")
            return texts(scenes[-1], scene)["mows_probe/axis"][0] if scenes else None

        def estimated() -> set[str]:
            return {f"B∥ {f.field_along_axis_t * 1e6:.4g} ± {f.field_along_axis_std_t * 1e6:.2g} µT" for f in fields}

        ros.wait_for(lambda: axis_label() in estimated(), "the scene's axis label among the field estimates")
        # A sweep on /mows/sweep: its field arrow, |B| ± σ, in the next scene.
        publisher = ros.node.create_publisher(SweepDecomposition, "mows/sweep", MAP_QOS)
        sweep = sweep_message()
        publisher.publish(sweep)
        magnitude, sigma = field_magnitude(sweep.field_t, np.reshape(sweep.field_covariance_t2, (2, 2)))
        expected = f"B {magnitude * 1e6:.4g} ± {sigma * 1e6:.2g} µT"

        def swept():
            return any("probe_0/field" in texts(m, scene) for m in client.payloads("/mows/viz/scene"))

        ros.wait_for(swept, "the sweep's arrows")
        latest = next(
            texts(m, scene) for m in reversed(client.payloads("/mows/viz/scene")) if "probe_0/field" in texts(m, scene)
        )
        assert latest["probe_0/field"][0] == expected
        assert latest["probe_0/field"][1].startswith("G1 ") and math.isfinite(magnitude)
        # The mount's frames, turned by the stage.
        frames = client.channel("/mows/viz/frames")
        ros.wait_for(lambda: client.payloads("/mows/viz/frames"), "the mount's frames")
        types = descriptors(base64.b64decode(frames["schema"]))
        transforms = decode(client.payloads("/mows/viz/frames")[-1], frames["schemaName"], types)["transforms"]
        assert {t["child_frame_id"] for t in transforms} >= {"mows_probe", "fluxgate_near", "fluxgate_far"}
    finally:
        client.close()
        graph.terminate()
        graph.wait(30)
    assert graph.returncode == 0, log(graph)
