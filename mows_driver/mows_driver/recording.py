"""Recording what the driver publishes, and what the graph concludes from it, into one rosbag2
bag (MCAP storage, metadata version 9) with ``rosbags``, which Jazzy's ``ros2 bag info/play``
read.

Messages are serialised with ``rclpy.serialization`` (the same CDR as rosbags) and written
before they are published, so a subscriber never receives a message the bag lacks. Each
topic is stored with its message definition and the QoS it is published with, so that
``ros2 bag play`` offers it the same way. The bag is complete once :meth:`close` has written
its summary and metadata (the driver closes it on SIGINT and SIGTERM); after a SIGKILL all
but the last chunk survive (:class:`mows.device.recording.bags.Recording`) and ``mows bag repair``
rebuilds the bag from them.
"""

import threading

from rclpy.qos import QoSProfile
from rclpy.serialization import serialize_message
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from mows.device.recording import bags

UNSET = QosTime(0, 0)  # rosbag2's "default" for deadline, lifespan and lease duration


def bag_qos(profile: QoSProfile) -> Qos:
    """The rosbags form of an rclpy QoS profile (both use rmw's enum numbers)."""
    return Qos(
        QosHistory(int(profile.history)),
        profile.depth,
        QosReliability(int(profile.reliability)),
        QosDurability(int(profile.durability)),
        UNSET,
        UNSET,
        QosLiveliness(int(profile.liveliness)),
        UNSET,
        False,
    )


class BagRecorder:
    """A new bag at ``path`` (which must not exist: :class:`mows.device.recording.bags.BagError`) for
    ``topics``: {name: (msgtype, QoS)}. Written from the driver's streaming thread (what it
    publishes) and its executor (what it hears of the graph), one at a time."""

    def __init__(self, path: str, topics: dict[str, tuple[str, QoSProfile]]):
        self._recording = bags.Recording(
            path, {topic: (msgtype, [bag_qos(qos)]) for topic, (msgtype, qos) in topics.items()}
        )
        self.path = self._recording.path
        self._lock = threading.Lock()
        self._closed = False  # a conclusion heard while the bag closes is not written

    @property
    def messages(self) -> int:
        return self._recording.messages

    def write(self, topic: str, message, timestamp_ns: int) -> None:
        raw = serialize_message(message)
        with self._lock:
            if not self._closed:
                self._recording.write(topic, raw, timestamp_ns)

    def close(self) -> None:
        with self._lock:
            if not self._closed:
                self._closed = True
                self._recording.close()


def open_recorder(path: str, topics: list) -> BagRecorder | None:
    """A new bag at ``path`` of ``topics`` [(name, message class, its QoS)]; None for ''."""
    if not path:
        return None
    return BagRecorder(path, {name: (message_type(cls), qos) for name, cls, qos in topics})


def message_type(cls) -> str:
    """The interface name of a generated message class, e.g. ``mows_msgs/msg/MagnetometerBlock``."""
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"
