"""Tracking mode in the graph: the driver (simulated device) with ``tracking:=true`` and the
estimator publish B along the probe axis continuously on /mows/field and /mows/magnetic_field.
The rate is counted per device second (the messages' device-clock stamps), never against the
wall clock; every wait ends as soon as its condition holds."""

import math

import pytest
from mows_msgs.msg import FieldEstimate
from sensor_msgs.msg import MagneticField

from mows.records import stamps
from mows_bringup.nodes import NODES
from mows_driver.parameters import PARAMETERS
from mows_ros.qos import RESULT_QOS, STREAM_QOS

pytestmark = pytest.mark.ros

UPDATES = 12
TARGET_STD_T = 0.2e-6  # the driver's default tracking_target_std_t


def test_tracking_is_off_by_default(ros, start):
    assert next(p for p in PARAMETERS if p.name == "tracking").default is False
    start(*NODES[0].command([]))
    heard = ros.diagnostics_of("/driver")
    ros.wait_for(lambda: "tracking" in heard, "the driver's diagnostics")
    assert heard["tracking"] == "False" and heard["tracking_stopped_reason"] == ""  # it never ran


def test_tracking_publishes_the_field_at_two_updates_per_device_second(ros, start):
    fields: list[FieldEstimate] = []
    magnetic: list[MagneticField] = []
    ros.node.create_subscription(FieldEstimate, "/mows/field", fields.append, RESULT_QOS)
    ros.node.create_subscription(MagneticField, "/mows/magnetic_field", magnetic.append, STREAM_QOS)
    start(*NODES[1].command([]))
    start(*NODES[0].command(["-p", "tracking:=true"]))
    ros.wait_for(lambda: len(fields) >= UPDATES and magnetic, f"{UPDATES} field estimates", bound_s=240.0)
    device_s = [stamps.seconds(f.header.stamp) for f in fields]
    assert device_s == sorted(device_s)
    rate = (len(fields) - 1) / (device_s[-1] - device_s[0])
    assert rate >= 2.0, rate
    assert len({f.cycle_id for f in fields}) >= 2  # chained cycles
    for f in fields:
        assert f.status == 0 and math.isfinite(f.field_along_axis_t)
        assert f.field_along_axis_std_t <= 1.5 * TARGET_STD_T  # the plan sits at the bound: the fit's σ near it
    assert all(math.isfinite(m.magnetic_field.x) for m in magnetic)
