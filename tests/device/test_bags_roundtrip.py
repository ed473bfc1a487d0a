"""Every mows_msgs type through a rosbag2 MCAP bag (mows.device.recording.bags), and rosbags' CDR against
rclpy's."""

import pytest
import yaml
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.highlevel import AnyReader
from rosbags.typesys import Stores, get_typestore

from message_equality import assert_same
from mows.device.recording import bags
from rclpy_conversion import rclpy_class, to_rclpy
from samples import BAG_TYPES, sample_message


@pytest.mark.parametrize("msgtype", BAG_TYPES)
def test_the_comparison_notices_a_changed_sample(msgtype):
    with pytest.raises(AssertionError):
        assert_same(sample_message(msgtype, offset=1), sample_message(msgtype))


@pytest.mark.parametrize("msgtype", BAG_TYPES)
def test_every_type_comes_back_equal_from_an_mcap_bag(tmp_path, msgtype):
    written = [bags.BagMessage("/mows/test", msgtype, 1_000 + i, sample_message(msgtype, offset=i)) for i in range(2)]
    bags.write_bag(tmp_path / "bag", written)
    read = list(bags.read_bag(tmp_path / "bag"))
    assert [m[:3] for m in read] == [m[:3] for m in written]
    for got, sent in zip(read, written):
        assert_same(got.message, sent.message)


def test_bags_are_rosbag2_mcap_version_9_with_their_definitions(tmp_path):
    msgtype = "mows_msgs/msg/MagnetometerBlock"
    sent = sample_message(msgtype)
    bags.write_bag(tmp_path / "bag", [bags.BagMessage("/mows/raw", msgtype, 5, sent)])
    metadata = yaml.safe_load((tmp_path / "bag" / "metadata.yaml").read_text())
    info = metadata["rosbag2_bagfile_information"]
    assert (info["version"], info["storage_identifier"], info["ros_distro"]) == (9, "mcap", "jazzy")
    # A reader that has never seen mows_msgs learns the types from the bag itself.
    plain = get_typestore(Stores.ROS2_JAZZY)
    with AnyReader([tmp_path / "bag"], default_typestore=plain) as reader:
        ((connection, _, raw),) = list(reader.messages())
        assert_same(reader.deserialize(raw, connection.msgtype), sent)


def test_reading_selects_topics(tmp_path):
    msgtype = "mows_msgs/msg/FieldEstimate"
    written = [
        bags.BagMessage(topic, msgtype, t, sample_message(msgtype, offset=t))
        for t, topic in enumerate(["/a", "/b", "/a"])
    ]
    bags.write_bag(tmp_path / "bag", written)
    assert [m.timestamp_ns for m in bags.read_bag(tmp_path / "bag", topics=["/a"])] == [0, 2]
    assert list(bags.read_bag(tmp_path / "bag", topics=["/missing"])) == []


def test_definitions_fall_back_to_the_repository(monkeypatch):
    monkeypatch.setenv("AMENT_PREFIX_PATH", "")
    assert bags.interface_directory() == bags.REPOSITORY_PACKAGE
    assert sorted(bags.interface_types(bags.REPOSITORY_PACKAGE)) == sorted(BAG_TYPES)


def test_a_stale_link_in_a_symlink_install_is_not_an_interface(tmp_path):
    """A colcon --symlink-install keeps its links to definitions renamed since; they define nothing."""
    for kind in ("msg", "srv", "action"):
        (tmp_path / kind).mkdir()
        for source in sorted((bags.REPOSITORY_PACKAGE / kind).glob(f"*.{kind}")):
            (tmp_path / kind / source.name).symlink_to(source)
    (tmp_path / "srv" / "Renamed.srv").symlink_to(tmp_path / "gone.srv")
    assert sorted(bags.interface_types(tmp_path)) == sorted(BAG_TYPES)


def test_a_service_definition_needs_its_two_parts():
    with pytest.raises(ValueError, match="2 parts, found 3"):
        bags.split_definition("int32 a\n---\nint32 b\n---\nint32 c\n", "srv")


@pytest.mark.ros
@pytest.mark.parametrize("msgtype", ["mows_msgs/msg/MagnetometerBlock", "mows_msgs/action/RotationSweep_Result"])
def test_rclpy_and_rosbags_read_each_others_cdr(msgtype):
    sample = sample_message(msgtype)
    cls = rclpy_class(msgtype)
    as_rclpy = to_rclpy(sample, cls)
    store = bags.typestore()
    assert_same(store.deserialize_cdr(serialize_message(as_rclpy), msgtype), sample)
    assert_same(deserialize_message(bytes(store.serialize_cdr(sample, msgtype)), cls), as_rclpy)


@pytest.mark.ros
@pytest.mark.parametrize("setup", ["x", "xyzw"])
def test_an_excitation_of_one_probe_from_rclpy_is_read_despite_its_trailing_bytes(setup):
    """One probe: the probe lists are empty, and rclpy's CDR then runs 4–8 bytes past the last
    field, more than rosbags' own check allows; every field still reads back as written."""
    from mows_msgs.msg import ExcitationState
    from rosbags.serde import SerdeError

    msgtype = "mows_msgs/msg/ExcitationState"
    raw = serialize_message(ExcitationState(phase=3, frequency_hz=112.5, theta0_rad=0.4, setup=setup))
    store = bags.typestore()
    with pytest.raises(SerdeError, match="size mismatch"):
        store.deserialize_cdr(raw, msgtype)
    read = bags.deserialize_cdr(store, msgtype, raw)
    assert (read.phase, read.frequency_hz, read.theta0_rad, read.setup) == (3, 112.5, 0.4, setup)
    assert len(read.probe_ids) == len(read.probe_frequency_hz) == len(read.probe_theta0_rad) == 0
    with pytest.raises(ValueError, match="bytes after the message's last field"):
        bags.deserialize_cdr(store, msgtype, raw + bytes(16))
