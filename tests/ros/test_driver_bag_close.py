"""The driver's bag keeps a conclusion that reached the node just before the bag closed. A
graph is stopped as soon as its requester has the answer, which can be before the driver's
executor has taken the map the mapper published a moment earlier."""

import pytest
import rclpy
from mows_msgs.msg import FieldMap

from mows.device.recording.bags import read_bag
from mows_driver.outputs import DriverOutputs
from mows_ros.qos import MAP_QOS

pytestmark = pytest.mark.ros


def test_a_map_the_executor_has_not_taken_is_in_the_closed_bag(ros, tmp_path):
    driver = rclpy.create_node("driver_bag_close")  # never spun: only closing the bag takes it
    try:
        outputs = DriverOutputs(driver)
        outputs.record(str(tmp_path / "bag"))
        heard: list = []
        ros.node.create_subscription(FieldMap, "/mows/field_map", heard.append, MAP_QOS)
        publisher = ros.node.create_publisher(FieldMap, "/mows/field_map", MAP_QOS)
        ros.wait_for(lambda: publisher.get_subscription_count() >= 2, "both readers of the map")
        sent = FieldMap()
        sent.header.frame_id = "sent_before_the_close"
        publisher.publish(sent)
        ros.wait_for(lambda: heard, "the map delivered on this host")  # the same transport as the driver's
        outputs.close()
    finally:
        driver.destroy_node()
    maps = [item.message for item in read_bag(tmp_path / "bag", topics=["/mows/field_map"])]
    assert [m.header.frame_id for m in maps] == ["sent_before_the_close"]
