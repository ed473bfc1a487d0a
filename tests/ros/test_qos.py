"""The graph's QoS profiles do what their names promise."""

import pytest
from std_msgs.msg import String

from mows_ros.qos import MAP_QOS, STREAM_QOS

pytestmark = pytest.mark.ros


def test_a_late_subscriber_gets_the_latest_map(ros):
    publisher = ros.node.create_publisher(String, "map", MAP_QOS)
    for text in ("older", "latest"):
        publisher.publish(String(data=text))
    received = []
    ros.node.create_subscription(String, "map", received.append, MAP_QOS)
    ros.wait_for(lambda: received, "the map")
    assert received[0].data == "latest"


def test_a_stream_subscriber_hears_a_reliable_publisher(ros):
    publisher = ros.node.create_publisher(String, "stream", 10)
    received = []
    ros.node.create_subscription(String, "stream", received.append, STREAM_QOS)
    ros.wait_for(publisher.get_subscription_count, "the subscription to match")
    publisher.publish(String(data="block"))
    ros.wait_for(lambda: received, "the block")
    assert received[0].data == "block"
