"""Our bags say Jazzy wherever rosbag2 on Jazzy says which distribution wrote them: in
metadata.yaml, in the MCAP file's rosbag2 Metadata record and in its Header, read by the MCAP
specification (tests/mcap_records.py), not by rosbags. Our reader still reads them."""

import yaml

from mcap_records import assert_jazzy
from mows.device.recording import bags

STRING = "std_msgs/msg/String"


def string(text: str):
    return bags.typestore().types[STRING](data=text)


def test_a_written_bag_says_jazzy_and_reads(tmp_path):
    bag = bags.write_bag(
        tmp_path / "bag", [bags.BagMessage("/chatter", STRING, 10 + i, string(f"{i}")) for i in range(3)]
    )
    assert_jazzy(bag)
    assert [(m.timestamp_ns, m.message.data) for m in bags.read_bag(bag)] == [(10, "0"), (11, "1"), (12, "2")]


def test_a_recording_says_jazzy_while_open_and_once_closed(tmp_path):
    recording = bags.Recording(tmp_path / "recording", {"/chatter": (STRING, [])})
    recording.write("/chatter", bags.typestore().serialize_cdr(string("one"), STRING), 5)
    info = yaml.safe_load((tmp_path / "recording" / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["ros_distro"] == "jazzy" and bags.OPEN_MARK in info["custom_data"]
    recording.close()
    assert_jazzy(tmp_path / "recording")
    assert [m.message.data for m in bags.read_bag(tmp_path / "recording")] == ["one"]
