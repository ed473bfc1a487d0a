"""Bags recorded before RingdownFit and SweepDecomposition carried a ``probe_id`` still read.

Requirement: a bag written with the earlier mows_msgs definitions (the same .msg texts without
``probe_id``) decodes into today's messages with every recorded field as written and
``probe_id`` 0, nested messages included (a RotationSweep feedback's fits); ``mows fit`` fits
its ring-downs and the driver's bag backend replays it whole, as it does a bag of today.
"""

import shutil

import pytest
from rosbags.typesys import Stores, get_typestore

from message_equality import field_names
from mows.cli import main as cli
from mows.device.backends.bag_backend import BagBackend
from mows.device.cycle.phases import CycleSettings
from mows.device.recording import bags
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import PRESETS, CurrentCap
from mows.sim.scenario import load_scenario
from recorded_bags import record_cycles
from samples import sample_message

ADDED = "probe_id"
CHANGED = ("msg/RingdownFit", "msg/SweepDecomposition")
NEW = ("msg/FieldMap", "msg/ProbeField")
# Today's types that hold a changed one, each in a bag of its own topic.
RECORDED = [
    "mows_msgs/msg/RingdownFit",
    "mows_msgs/msg/SweepDecomposition",
    "mows_msgs/action/RotationSweep_Feedback",
    "mows_msgs/action/RotationSweep_Result",
]


@pytest.fixture(scope="module")
def earlier_store(tmp_path_factory):
    """The Jazzy typestore with mows_msgs as it was before ``probe_id``."""
    directory = tmp_path_factory.mktemp("mows_msgs")
    shutil.copytree(bags.interface_directory(), directory / "pkg", symlinks=False)
    for name in CHANGED:
        path = directory / "pkg" / f"{name}.msg"
        kept = [line for line in path.read_text().splitlines() if not line.startswith(f"uint8 {ADDED}")]
        assert len(kept) == len(path.read_text().splitlines()) - 1
        path.unlink()
        path.write_text("\n".join(kept) + "\n")
    for name in NEW:
        (directory / "pkg" / f"{name}.msg").unlink()
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(bags.interface_types(directory / "pkg"))
    return store


def assert_kept(read, written, path="message"):
    """Every field of ``written`` is in ``read`` as written; ``read``'s other fields are the
    added ``probe_id``, at 0."""
    old, new = field_names(written), field_names(read)
    if old is None:
        assert_values_equal(read, written, path)
        return
    assert [name for name in new if name not in old] == ([ADDED] if ADDED in new and ADDED not in old else [])
    if ADDED in new and ADDED not in old:
        assert getattr(read, ADDED) == 0, path
    for name in old:
        assert_kept(getattr(read, name), getattr(written, name), f"{path}.{name}")


def assert_values_equal(read, written, path):
    if isinstance(written, list):
        assert len(read) == len(written), path
        for index, (a, b) in enumerate(zip(read, written)):
            assert_kept(a, b, f"{path}[{index}]")
    else:
        assert (read == written).all() if hasattr(written, "shape") else read == written, path


def test_earlier_messages_read_as_today_with_probe_id_zero(tmp_path, earlier_store):
    written = [
        bags.BagMessage(f"/t{i}", msgtype, 1_000 + i, sample_message(msgtype, earlier_store))
        for i, msgtype in enumerate(RECORDED)
    ]
    bags.write_bag(tmp_path / "bag", written, earlier_store)
    read = list(bags.read_bag(tmp_path / "bag"))
    assert [m[:3] for m in read] == [m[:3] for m in written]
    current = bags.typestore()
    for got, sent in zip(read, written):
        assert type(got.message) is current.types[got.msgtype]
        assert_kept(got.message, sent.message)
    assert read[2].message.fits and all(fit.probe_id == 0 for fit in read[2].message.fits)


def test_todays_definition_alone_misreads_some_earlier_fits(earlier_store):
    """What the reader must not do. The new byte sits where the earlier fit has the padding
    before theta0_rad, so today's definition reads some earlier fits right by luck: those
    whose message leaves no padding come out wrong."""
    msgtype = "mows_msgs/msg/RingdownFit"
    kept = []
    for length in range(8):
        written = sample_message(msgtype, earlier_store)
        written.message = "x" * length
        earlier_bytes = earlier_store.serialize_cdr(written, msgtype)
        kept.append(naive_decoding_from(earlier_bytes, written))
    assert not all(kept) and any(kept)


def naive_decoding_from(earlier_bytes: bytes, written) -> bool:
    try:
        assert_kept(bags.typestore().deserialize_cdr(earlier_bytes, "mows_msgs/msg/RingdownFit"), written)
    except Exception:  # noqa: BLE001 - a decoding error or a changed field: not kept
        return False
    return True


@pytest.fixture(scope="module")
def earlier_recording(tmp_path_factory, earlier_store):
    """A driver-like bag of two simulated cycles, with fits and a sweep, in the earlier definitions."""
    directory = tmp_path_factory.mktemp("earlier")
    today, _ = record_cycles(directory / "today", load_scenario(), (0.0, 60.0), 9)
    messages = list(bags.read_bag(today))
    for k, msgtype in enumerate(RECORDED[:2]):
        topic = "/mows/ringdown" if "Ringdown" in msgtype else "/mows/sweep"
        messages.append(
            bags.BagMessage(topic, msgtype, messages[-1].timestamp_ns + k, sample_message(msgtype, earlier_store))
        )
    return bags.write_bag(directory / "earlier", messages, earlier_store), len(messages) - 2


def test_mows_fit_fits_an_earlier_bag(earlier_recording, capsys):
    path, _ = earlier_recording
    assert cli.main(["fit", str(path)]) == 0
    assert "2 of 2 ring-downs fitted" in capsys.readouterr().out


def test_the_driver_replays_an_earlier_bag_whole(earlier_recording):
    path, recorded = earlier_recording
    cap = CurrentCap(10.0)
    config = SessionConfig(
        0.025, CycleSettings(), PRESETS["largest_spacing"](current_limit_a=cap.limit_a), cap, 110.0, fit_tuning
    )
    backend = BagBackend(path, rate=1000.0)
    session = DeviceSession(backend, config)
    for _ in range(10_000):
        if session.health()["link"] == "finished":
            break
        session.step(0.01)
    assert session.health()["link"] == "finished"
    assert backend.replayed == recorded and backend.skipped == {}
    session.close()
