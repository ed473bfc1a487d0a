"""The viz node: the graph's topics fed to :class:`mows.viz.view.View`, its channels served to
Foxglove over the WebSocket protocol by foxglove-sdk (docs/visualisation.md).

Subscribes (names relative, as the graph's) to ``mows/raw``, ``mows/excitation``,
``mows/joint_states``, ``mows/ringdown``, ``mows/field``, ``mows/sweep``, ``mows/field_map``,
``mows/model_report`` and ``/diagnostics``, each with its publisher's QoS, and logs what the View
shows on the channels of :mod:`mows.viz.channels` (``/mows/viz/...``), the raw stream at its
samples' device time, the rest at the host's clock. The server runs while the node is active,
on ``host``:``port``; the address to open is logged and on /diagnostics (``address``). Each
channel's last message is re-sent to a client that subscribes later (:mod:`mows.viz.live`).

The ring-downs are drawn on a thread of their own, in the order their samples complete: a
drawing can take a second under load, and on the executor's thread it would hold back the
stream, whose blocks the fit's window needs (the fit then drawn over NaN, or dropped). At a
stop the ring-downs still queued are drawn for at most ``DRAW_AT_STOP_S`` (mows-graph aborts a
node that has not stopped 10 s after its signal); /diagnostics count the ring-downs drawn and
those that were not (``ringdowns_drawn``, ``ringdowns_not_drawn``: samples no longer kept, or
still queued at a stop).
"""

import queue
import threading

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

from mows.viz.live import LiveChannels
from mows.viz.mount import Mount
from mows.viz.view import RingdownToDraw, Shown, View, ViewSettings
from mows_ros.diagnostics import DIAGNOSTICS_DEPTH, DIAGNOSTICS_TOPIC, Health
from mows_ros.node import MowsNode
from mows_ros.params import parameter_values
from mows_ros.process import run_node
from mows_ros.qos import EXCITATION_QOS, JOINT_QOS, MAP_QOS, RESULT_QOS, STREAM_QOS, maps_qos
from mows_ros.wall import SYSTEM
from mows_viz.parameters import PARAMETERS, view_settings

NODE_NAME = "viz"
DRAW_AT_STOP_S = 5.0
MAPS = maps_qos(4)  # /mows/sweep keeps one per probe (at most 4)


class VizNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self._view: View | None = None
        self._server = None
        self._channels: LiveChannels | None = None
        self._logged = 0
        self._count_lock = threading.Lock()
        self._to_draw: queue.SimpleQueue[RingdownToDraw | None] = queue.SimpleQueue()
        self._drawer: threading.Thread | None = None
        self._stop_drawing = threading.Event()
        self._drawn = self._undrawn = 0
        feeds = (
            (MagnetometerBlock, "mows/raw", lambda view, msg, _now: view.raw_points(msg), STREAM_QOS),
            (ExcitationState, "mows/excitation", View.on_excitation, EXCITATION_QOS),
            (JointState, "mows/joint_states", View.on_joint_states, JOINT_QOS),
            (RingdownFit, "mows/ringdown", lambda view, msg, now: view.keep_fit(msg, now) or [], RESULT_QOS),
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
                for window in self._view.ready_ringdowns():
                    self._to_draw.put(window)

        return take

    def _log(self, shown: Shown) -> None:
        if self._channels is not None:
            self._channels.log(shown)
            with self._count_lock:
                self._logged += 1

    def _drawing(self, settings: ViewSettings) -> None:
        while (ringdown := self._to_draw.get()) is not None:
            if self._stop_drawing.is_set():
                self._undrawn += 1
                continue
            self._log(ringdown.drawn(settings))
            self._drawn += 1

    # --- the lifecycle -------------------------------------------------------------------
    def configure(self) -> None:
        mount_file = self._param("mount_file")
        mount = None
        if mount_file:
            with open(mount_file, encoding="utf-8") as text:
                mount = Mount(text.read())
        self._view = View(view_settings(parameter_values(self, PARAMETERS)), mount)
        self._channels = LiveChannels()

    def activate(self) -> None:
        self._server = foxglove.start_server(
            name="mows", host=self._param("host"), port=self._param("port"), server_listener=self._channels
        )
        self._stop_drawing.clear()
        self._drawer = threading.Thread(
            target=self._drawing, args=(self._view.settings,), name="viz-drawing", daemon=True
        )
        self._drawer.start()
        self.get_logger().info(f"Foxglove: open ws://{self.address()} (Open connection, Foxglove WebSocket)")

    def address(self) -> str:
        return f"{self._param('host')}:{self._server.port}" if self._server is not None else ""

    def deactivate(self) -> None:
        if self._drawer is not None:  # the ring-downs already queued drawn first, for a while
            self._to_draw.put(None)
            self._drawer.join(DRAW_AT_STOP_S)
            self._stop_drawing.set()
            self._drawer.join()  # the drawing under way, then the rest counted
            self._drawer = None
        if self._server is not None:
            self._server.stop()
            self._server = None

    def cleanup(self) -> None:
        self.deactivate()
        if self._channels is not None:
            self._channels.close()
            self._channels = None
        self._view = None

    def health(self) -> Health:
        base = super().health()
        address = f"ws://{self.address()}" if self.address() else ""
        lost = self._view.fits_without_samples if self._view is not None else 0
        counts = {"ringdowns_drawn": self._drawn, "ringdowns_not_drawn": lost + self._undrawn}
        return Health(
            base.level, base.message, {**base.values, "address": address, "messages_logged": self._logged, **counts}
        )


def main(args=None) -> int:
    return run_node(VizNode, args)
