"""The viz node: the graph's topics fed to :class:`mows.viz.view.View`, its channels served to
Foxglove over the WebSocket protocol by foxglove-sdk (docs/visualisation.md).

Subscribes (names relative, as the graph's) to ``mows/raw``, ``mows/excitation``,
``mows/joint_states``, ``mows/ringdown``, ``mows/field``, ``mows/sweep``, ``mows/field_map``,
``mows/model_report`` and ``/diagnostics``, each with its publisher's QoS, and logs what the View
shows on the channels of :mod:`mows.viz.channels` (``/mows/viz/...``), the raw stream at its
samples' device time, the rest at the host's clock. The server runs while the node is active,
on ``host``:``port``; the address to open is logged and on /diagnostics (``address``).
"""

import foxglove
from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.msg import (
    ExcitationState,
    FieldEstimate,
    FieldMap,
    MagnetometerBlock,
    ModelReport,
    RingdownFit,
    SweepDecomposition,
    WorkspaceModel,
)
from sensor_msgs.msg import JointState

from mows.viz import channels
from mows.viz.mount import Mount
from mows.viz.view import Shown, View
from mows_ros.diagnostics import DIAGNOSTICS_DEPTH, DIAGNOSTICS_TOPIC, Health
from mows_ros.node import MowsNode
from mows_ros.params import parameter_values
from mows_ros.process import run_node
from mows_ros.qos import EXCITATION_QOS, JOINT_QOS, MAP_QOS, RESULT_QOS, STREAM_QOS, maps_qos
from mows_ros.wall import SYSTEM
from mows_viz.parameters import PARAMETERS, view_settings

NODE_NAME = "viz"
MAPS = maps_qos(4)  # /mows/sweep keeps one per probe (at most 4)


class VizNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self._view: View | None = None
        self._server = None
        self._channels: dict[str, foxglove.Channel] = {}
        self._logged = 0
        feeds = (
            (MagnetometerBlock, "mows/raw", lambda view, msg, _now: view.on_raw(msg), STREAM_QOS),
            (ExcitationState, "mows/excitation", View.on_excitation, EXCITATION_QOS),
            (JointState, "mows/joint_states", View.on_joint_states, JOINT_QOS),
            (RingdownFit, "mows/ringdown", View.on_ringdown, RESULT_QOS),
            (FieldEstimate, "mows/field", View.on_field, RESULT_QOS),
            (SweepDecomposition, "mows/sweep", View.on_sweep, MAPS),
            (FieldMap, "mows/field_map", View.on_field_map, MAP_QOS),
            (ModelReport, "mows/model_report", View.on_model_report, MAP_QOS),
            (WorkspaceModel, "mows/workspace_model", View.on_workspace_model, MAP_QOS),
            (DiagnosticArray, DIAGNOSTICS_TOPIC, View.on_diagnostics, DIAGNOSTICS_DEPTH),
        )
        for cls, topic, feed, qos in feeds:
            self.create_subscription(cls, topic, self.when_active(self._feeding(feed)), qos)

    def _param(self, name):
        return self.get_parameter(name).value

    def _feeding(self, feed):
        def take(msg) -> None:
            if self._view is not None:
                for shown in feed(self._view, msg, SYSTEM.now().nanoseconds):
                    self._log(shown)

        return take

    def _log(self, shown: Shown) -> None:
        self._channels[shown.topic].log(channels.payload(shown), log_time=int(shown.log_time_ns))
        self._logged += 1

    # --- the lifecycle -------------------------------------------------------------------
    def configure(self) -> None:
        mount_file = self._param("mount_file")
        mount = None
        if mount_file:
            with open(mount_file, encoding="utf-8") as text:
                mount = Mount(text.read())
        self._view = View(view_settings(parameter_values(self, PARAMETERS)), mount)
        # Every channel advertised from the start, so a client sees them all before data comes.
        for topic in channels.TOPICS:
            found = channels.schema(topic)
            self._channels[topic] = foxglove.Channel(
                topic,
                schema=foxglove.Schema(name=found.name, encoding=found.encoding, data=found.data),
                message_encoding=found.message_encoding,
            )

    def activate(self) -> None:
        self._server = foxglove.start_server(name="mows", host=self._param("host"), port=self._param("port"))
        self.get_logger().info(f"Foxglove: open ws://{self.address()} (Open connection, Foxglove WebSocket)")

    def address(self) -> str:
        return f"{self._param('host')}:{self._server.port}" if self._server is not None else ""

    def deactivate(self) -> None:
        if self._server is not None:
            self._server.stop()
            self._server = None

    def cleanup(self) -> None:
        self.deactivate()
        for channel in self._channels.values():
            channel.close()
        self._channels.clear()
        self._view = None

    def health(self) -> Health:
        base = super().health()
        address = f"ws://{self.address()}" if self.address() else ""
        return Health(base.level, base.message, {**base.values, "address": address, "messages_logged": self._logged})


def main(args=None) -> int:
    return run_node(VizNode, args)
