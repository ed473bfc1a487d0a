"""The driver's topics, and the bag they are recorded into: what one step of the device
session yields, published in order, and what the graph concludes from it.

Blocks go out on ``mows/raw`` only while the session is armed (the node active), each with the
stage's angle on ``mows/joint_states`` when the stage is known; phase events on
``mows/excitation`` and supply ramps on ``mows/supply`` in every state. Each message is written
to the bag (when recording) before it is published, so that a subscriber never has a message
the bag lacks. Beside them the bag holds what the graph concludes, as the driver hears it: the
estimator's fits and field estimates, the mapper's sweeps, field maps and model reports, and
/diagnostics, so that one recording can be analysed later (``mows lab compare BAG`` reads the
fits, of one probe or several). Link changes and forced coil cuts are logged as they happen.
"""

import time

from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.msg import (
    ExcitationState,
    FieldEstimate,
    FieldMap,
    MagnetometerBlock,
    ModelReport,
    RingdownFit,
    SupplyState,
    SweepDecomposition,
    WorkspaceModel,
)
from rclpy.exceptions import InvalidHandle
from rclpy.node import Node
from sensor_msgs.msg import JointState

from mows.device.cycle.phases import Phase
from mows.device.stream.session import DeviceSession, Output
from mows_driver.messages import block_msg, excitation_msg, joint_state_msg, supply_msg
from mows_driver.recording import open_recorder
from mows_ros.qos import EXCITATION_QOS, JOINT_QOS, MAP_QOS, RESULT_QOS, STREAM_QOS, maps_qos

RAW_TOPIC = "mows/raw"
EXCITATION_TOPIC = "mows/excitation"
SUPPLY_TOPIC = "mows/supply"
JOINT_STATES_TOPIC = "mows/joint_states"
# What the graph concludes, recorded beside the stream: (topic, message, QoS to hear it with).
# The maps are heard as they are offered (transient local), the sweep's one per probe.
CONCLUSIONS = (
    ("mows/ringdown", RingdownFit, RESULT_QOS),
    ("mows/field", FieldEstimate, RESULT_QOS),
    ("mows/sweep", SweepDecomposition, maps_qos(16)),
    ("mows/field_map", FieldMap, MAP_QOS),
    ("mows/model_report", ModelReport, MAP_QOS),
    ("mows/workspace_model", WorkspaceModel, MAP_QOS),
    ("/diagnostics", DiagnosticArray, RESULT_QOS),
)


class DriverOutputs:
    """The driver's publishers on ``node``, its bag while one is open, and what they have sent."""

    def __init__(self, node: Node):
        self._node = node
        self._logger = node.get_logger()
        self._hearing: list = []  # the subscriptions to the graph's conclusions while recording
        self.raw = node.create_publisher(MagnetometerBlock, RAW_TOPIC, STREAM_QOS)
        self.excitation = node.create_publisher(ExcitationState, EXCITATION_TOPIC, EXCITATION_QOS)
        self.supply = node.create_publisher(SupplyState, SUPPLY_TOPIC, EXCITATION_QOS)
        self.joints = node.create_publisher(JointState, JOINT_STATES_TOPIC, JOINT_QOS)
        self.recorder = None
        self.blocks_published = 0

    def record(self, path: str) -> None:
        """Record what is published, and the graph's conclusions, into a new bag at ``path``
        ('' records nothing)."""
        own = [(p.topic_name, p.msg_type, qos) for p, qos in self._own_topics()]
        heard = [(self._node.resolve_topic_name(name), cls, qos) for name, cls, qos in CONCLUSIONS]
        self.recorder = open_recorder(path, own + heard)
        if self.recorder is not None:
            self._hearing = [
                self._node.create_subscription(cls, name, self._recording(name), qos) for name, cls, qos in heard
            ]

    def _own_topics(self) -> list:
        return [
            (self.raw, STREAM_QOS),
            (self.excitation, EXCITATION_QOS),
            (self.supply, EXCITATION_QOS),
            (self.joints, JOINT_QOS),  # the mount's frames of a recording (``mows viz BAG --mount``)
        ]

    def _recording(self, topic: str):
        def write(message) -> None:
            if self.recorder is not None:
                self.recorder.write(topic, message, time.time_ns())

        return write

    def close(self) -> None:
        """Closes the bag: complete, with its summary and metadata. A conclusion that reached
        the node but not yet its executor (a map published just before a shutdown) is written
        first: the graph stops as soon as its requester has the answer."""
        for subscription in self._hearing:
            for message in _waiting(subscription):
                subscription.callback(message)
            self._node.destroy_subscription(subscription)
        self._hearing = []
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None

    def counts(self) -> dict:
        return {
            "blocks_published": self.blocks_published,
            "recorded_messages": self.recorder.messages if self.recorder else 0,
        }

    def publish(self, output: Output, session: DeviceSession, values: dict) -> None:
        """What one step of ``session`` yielded, with the node's parameter ``values`` (frames)."""
        for link in output.links:  # in every state, not only in a cycle
            # One call site per severity: rclpy refuses to change a call site's severity.
            if link.up:
                self._logger.info(f"link up: {link.reason}")
            else:
                self._logger.warning(f"link lost: {link.reason}")
        # Published only while armed (active): disarming flips it under the session's lock, so
        # no block with a sample read after the deactivation is published.
        for block in output.blocks if session.armed else ():
            sends = [(self.raw, block_msg(block, session.backend.info, values["frame_id"], values["sensor_frame_ids"]))]
            if session.stage_angle_rad is not None:  # the stage with every block: TF at its stamps
                sends.append((self.joints, joint_state_msg(block.stamp_ns, session.stage_angle_rad)))
            self._send(*sends)
            self.blocks_published += 1
        for event in output.events:
            self._send((self.excitation, excitation_msg(event, values["probe_frame_id"], session.epoch)))
            if event.phase == Phase.FAULT:
                self._logger.error(f"coils forced off: {event.reason}")
        for supply in output.supply:
            self._send((self.supply, supply_msg(supply, values["probe_frame_id"])))

    def _send(self, *sends) -> None:
        """Each (publisher, message) of ``sends`` written, then each published: a block and its
        joint state are in the bag together even when a shutdown stops the publishing between."""
        for publisher, message in sends:
            if self.recorder is not None:
                self.recorder.write(publisher.topic_name, message, time.time_ns())
        for publisher, message in sends:
            publisher.publish(message)


def _waiting(subscription) -> list:
    """The messages ``subscription`` holds that no callback has taken yet, as rclpy's executor
    takes them; none once its handle is gone."""
    taken: list = []
    try:
        with subscription.handle:
            while (message := subscription.handle.take_message(subscription.msg_type, subscription.raw)) is not None:
                taken.append(message[0])
    except InvalidHandle:
        pass
    return taken
