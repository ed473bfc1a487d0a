"""Recording what the driver publishes into a rosbag2 bag (MCAP storage, metadata version 9)
with ``rosbags``, which Jazzy's ``ros2 bag info/play`` read.

Messages are serialised with ``rclpy.serialization`` (the same CDR as rosbags) and written
before they are published, so a subscriber never receives a message the bag lacks. Each
topic is stored with its message definition and the QoS it is published with, so that
``ros2 bag play`` offers it the same way. The bag is only complete once :meth:`close` has
written its summary and metadata: the driver closes it on SIGINT and SIGTERM.
"""
from pathlib import Path

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
from rosbags.rosbag2 import StoragePlugin, Writer

from mows.device import bags

UNSET = QosTime(0, 0)  # rosbag2's "default" for deadline, lifespan and lease duration


def bag_qos(profile: QoSProfile) -> Qos:
    """The rosbags form of an rclpy QoS profile (both use rmw's enum numbers)."""
    return Qos(QosHistory(int(profile.history)), profile.depth, QosReliability(int(profile.reliability)),
               QosDurability(int(profile.durability)), UNSET, UNSET, QosLiveliness(int(profile.liveliness)),
               UNSET, False)


class BagRecorder:
    """A new bag at ``path`` (which must not exist) for ``topics``: {name: (msgtype, QoS)}.
    Used from one thread at a time (the driver's streaming thread, then its shutdown)."""

    def __init__(self, path: str, topics: dict[str, tuple[str, QoSProfile]]):
        self.path = Path(path)
        self.messages = 0
        self._writer = Writer(self.path, version=bags.BAG_VERSION, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        store = bags.typestore()
        self._connections = {
            topic: self._writer.add_connection(topic, msgtype, typestore=store, offered_qos_profiles=[bag_qos(qos)])
            for topic, (msgtype, qos) in topics.items()
        }

    def write(self, topic: str, message, timestamp_ns: int) -> None:
        self._writer.write(self._connections[topic], timestamp_ns, serialize_message(message))
        self.messages += 1

    def close(self) -> None:
        self._writer.close()


def open_recorder(path: str, publishers: list) -> BagRecorder | None:
    """A new bag at ``path`` of what ``publishers`` [(publisher, its QoS)] publish; None for ''."""
    if not path:
        return None
    return BagRecorder(path, {publisher.topic_name: (message_type(publisher.msg_type), qos)
                              for publisher, qos in publishers})


def message_type(cls) -> str:
    """The interface name of a generated message class, e.g. ``mows_msgs/msg/MagnetometerBlock``."""
    return f"{cls.__module__.split('.')[0]}/msg/{cls.__name__}"
