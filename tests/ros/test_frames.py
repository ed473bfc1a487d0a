"""Frames a robot can use: the URDF of the probe mount names every frame_id our messages carry,
its stage joint turns the probe the way θ0 does, its fluxgates sit where the estimator assumes;
the driver publishes the stage angle as sensor_msgs/JointState with the blocks' device stamps."""

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from ament_index_python.packages import get_package_share_directory
from mows_msgs.msg import MagnetometerBlock
from mows_msgs.srv import RunCycle
from sensor_msgs.msg import JointState

from mows.estimate.settings import probe_set
from mows.physics.pose import Pose, probe_axes
from mows.physics.probe import PAPER_PROBE
from mows.records import stamps
from mows_bringup.mount import probes_mount
from mows_bringup.nodes import NODES
from mows_driver import node as driver
from mows_driver.messages import STAGE_JOINT
from mows_estimator import parameters as estimator
from mows_mapper import parameters as mapper
from mows_ros.qos import JOINT_QOS, STREAM_QOS
from node_processes import START_S

pytestmark = pytest.mark.ros

URDF = Path(get_package_share_directory("mows_bringup")) / "urdf" / "mows_probe_mount.urdf"


def defaults(table) -> dict:
    return {spec.name: spec.default for spec in table}


@pytest.fixture(scope="module")
def mount():
    robot = ET.parse(URDF).getroot()
    links = {link.get("name") for link in robot.findall("link")}
    joints = {joint.get("name"): joint for joint in robot.findall("joint")}
    return links, joints


def rotation(axis, angle_rad) -> np.ndarray:
    """Rodrigues: the rotation by ``angle_rad`` about the unit ``axis`` (right hand)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle_rad) * cross + (1 - math.cos(angle_rad)) * cross @ cross


def origin(joint):
    element = joint.find("origin")
    xyz = np.array(element.get("xyz").split(), float)
    roll, pitch, yaw = np.array(element.get("rpy").split(), float)
    return xyz, rotation((0, 0, 1), yaw) @ rotation((0, 1, 0), pitch) @ rotation((1, 0, 0), roll)


def test_every_frame_we_publish_is_a_link_of_one_tree(mount):
    links, joints = mount
    d, e, m = defaults(driver.PARAMETERS), defaults(estimator.PARAMETERS), defaults(mapper.PARAMETERS)
    published = {d["frame_id"], *d["sensor_frame_ids"], d["probe_frame_id"], e["probe_frame_id"], m["frame_id"]}
    assert published <= links, published - links
    parents = {j.find("child").get("link"): j.find("parent").get("link") for j in joints.values()}
    roots = links - parents.keys()
    assert roots == {m["frame_id"]}  # everything hangs from the rotation plane: one joint attaches it


def test_the_stage_joint_turns_the_probe_as_theta0_does(mount):
    _, joints = mount
    stage = joints[STAGE_JOINT]
    assert stage.get("type") in ("continuous", "revolute")
    assert (stage.find("parent").get("link"), stage.find("child").get("link")) == ("mows_rotation_plane", "mows_probe")
    axis = np.array(stage.find("axis").get("xyz").split(), float)
    for theta0 in np.radians([0.0, 30.0, 135.0, -100.0]):
        # The probe's x' in the plane: the joint's rotation of x, against mows.physics.pose.
        np.testing.assert_allclose(rotation(axis, theta0) @ [1, 0, 0], probe_axes(theta0)[0], atol=1e-12)


def test_a_mount_of_several_probes_frames_each_at_its_place_turning_with_the_stage():
    probes = probe_set(
        "{0: 112.48, 1: {f00_hz: 125.0, position_m: [0.0, 0.05, 0.0]},"
        " 2: {f00_hz: 101.0, position_m: [0.01, -0.05, 0.002]}}",
        PAPER_PROBE,
    )
    robot = ET.fromstring(probes_mount(probes))
    links = {link.get("name") for link in robot.findall("link")}
    joints = {joint.get("name"): joint for joint in robot.findall("joint")}
    parents = {j.find("child").get("link"): j.find("parent").get("link") for j in joints.values()}
    assert links - parents.keys() == {"mows_rotation_plane"}  # still one tree
    for entry in probes:
        k = entry.probe_id
        plane, probe = f"mows_rotation_plane_{k}", f"mows_probe_{k}"  # the nodes' per-probe frames
        assert {plane, probe} <= links and parents[probe] == plane and parents[plane] == "mows_rotation_plane"
        at, turn = origin(joints[f"{plane}_mount"])
        stage = joints[f"mows_stage_{k}"]
        assert stage.find("mimic").get("joint") == "mows_stage" and stage.get("type") == "continuous"
        axis = np.array(stage.find("axis").get("xyz").split(), float)
        for theta0 in np.radians([0.0, 30.0, -100.0]):
            # The probe frame's origin is the magnet's rest position the estimator fits with, and
            # its x' is the probe's at θ0: each probe turns about its own magnet.
            pose = Pose(theta0_rad=theta0, magnet_position_m=entry.position_m)
            np.testing.assert_allclose(at, pose.magnet_position_m, atol=1e-15)
            np.testing.assert_allclose(turn @ rotation(axis, theta0) @ [1, 0, 0], pose.axes()[0], atol=1e-12)


def test_the_fluxgates_sit_where_the_estimator_assumes_and_sense_along_their_x(mount):
    _, joints = mount
    e = defaults(estimator.PARAMETERS)
    near, far = (origin(joints[f"{name}_mount"]) for name in defaults(driver.PARAMETERS)["sensor_frame_ids"])
    np.testing.assert_allclose(near[0], [e["sensor_distance_m"], 0, 0], atol=1e-12)
    np.testing.assert_allclose(far[0], [e["sensor_distance_m"] + e["sensor_spacing_m"], 0, 0], atol=1e-12)
    sensing = [e["sensor_axis_a"], e["sensor_axis_b"], 0.0]
    for _, turn in (near, far):
        np.testing.assert_allclose(turn @ [1, 0, 0], sensing, atol=1e-12)


def test_the_driver_publishes_the_stage_angle_with_every_block(ros, start):
    start(
        *NODES[0].command(
            ["-p", "theta0_rad:=0.5", "-p", "excite_s:=0.2", "-p", "ringdown_s:=0.2", "-p", "turn_settle_s:=0.1"]
        )
    )
    joints, blocks = [], []
    ros.node.create_subscription(JointState, "/mows/joint_states", joints.append, JOINT_QOS)
    ros.node.create_subscription(MagnetometerBlock, "/mows/raw", blocks.append, STREAM_QOS)
    ros.wait_for(lambda: len(joints) >= 5 and blocks, "joint states and blocks", START_S)  # the driver's start
    assert all(j.name == [STAGE_JOINT] and j.position[0] == 0.5 for j in joints)
    # Both streams are best-effort: a block or its joint state may be lost under load, so the
    # common stamp is looked for among everything heard so far, not among the first blocks only.
    ros.wait_for(
        lambda: (
            {stamps.nanoseconds(j.header.stamp) for j in joints} & {stamps.nanoseconds(b.header.stamp) for b in blocks}
        ),
        "a common stamp",
    )
    client = ros.node.create_client(RunCycle, "/driver/run_cycle")
    ros.wait_for(client.service_is_ready, "run_cycle")
    done = client.call_async(RunCycle.Request(theta0_rad=1.25, repeats=1, tuning_steps=0, gap_s=0.0))
    assert ros.wait_for(lambda: done.done() and done.result(), "the cycle").success
    heard = len(joints)
    ros.wait_for(lambda: len(joints) > heard, "joint states after the cycle")
    assert joints[-1].position[0] == 1.25
