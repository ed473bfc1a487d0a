"""The driver node as a process: the stream (device stamps, contiguous samples, saturation
flags), the run_cycle service end to end on the simulator, parameters, the emergency stop,
recording to a bag that survives SIGTERM, the bag backend's replay, and a 20 s live stream
with no unexplained gaps. Every wait ends as soon as its condition holds."""

import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from mows_msgs.msg import ExcitationState, MagnetometerBlock
from mows_msgs.srv import EmergencyStop, RunCycle, SetFieldCurrent
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.qos import QoSProfile, ReliabilityPolicy

from mcap_records import assert_jazzy
from mows.cli import main as cli
from mows.device.cycle.phases import Phase
from mows.device.recording import bags
from mows.device.serial.emulator import DeviceEmulator
from mows.records import stamps
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice
from mows_bringup.nodes import NODES
from mows_driver import node as driver
from mows_driver import outputs, services
from mows_ros.process import EXIT_BAD_PARAMETER
from mows_ros.qos import EXCITATION_QOS
from node_processes import log

pytestmark = pytest.mark.ros

RATE_HZ = 20_000.0
BLOCK = 500  # samples of a 25 ms block
# A subscriber that keeps up with bursts: best effort (what the sensor-data publisher offers).
RAW_QOS = QoSProfile(depth=1000, reliability=ReliabilityPolicy.BEST_EFFORT)
QUICK_CYCLES = ["-p", "excite_s:=0.3", "-p", "ringdown_s:=0.3", "-p", "turn_settle_s:=0.1"]


@pytest.fixture
def start_driver(start):
    """Starts the driver with extra ROS arguments (``start`` logs its output, kills it at the end)."""
    return lambda *ros_args: start(*NODES[0].command(list(ros_args)))


class Listener:
    """What the test node hears of the driver."""

    def __init__(self, ros):
        self.ros = ros
        self.blocks: list[MagnetometerBlock] = []
        self.states: list[ExcitationState] = []
        self.diagnostics: dict[str, str] = {}
        ros.node.create_subscription(MagnetometerBlock, "/mows/raw", self.blocks.append, RAW_QOS)
        ros.node.create_subscription(ExcitationState, "/mows/excitation", self.states.append, EXCITATION_QOS)
        ros.node.create_subscription(DiagnosticArray, "/diagnostics", self._diagnostics, 10)
        self.run_cycle = ros.node.create_client(RunCycle, "/driver/run_cycle")
        self.estop = ros.node.create_client(EmergencyStop, "/driver/emergency_stop")

    def _diagnostics(self, array: DiagnosticArray) -> None:
        for status in array.status:
            if status.name == "/driver":
                self.diagnostics = {kv.key: kv.value for kv in status.values}
                self.diagnostics["level"] = status.level

    def call(self, client, request):
        """Send ``request``; the future of its response."""
        self.ros.wait_for(lambda: client.service_is_ready(), f"the service {client.srv_name}")
        return client.call_async(request)

    def result(self, future):
        return self.ros.wait_for(lambda: future.done() and future.result(), "the service's response")

    def phases(self, cycle_id=None):
        return [Phase(s.phase) for s in self.states if cycle_id is None or s.cycle_id == cycle_id]


@pytest.fixture
def listen(ros):
    return Listener(ros)


def field(block) -> np.ndarray:
    return np.stack([np.frombuffer(c.field_t, float) for c in block.channels], axis=1)


def saturated(block) -> np.ndarray:
    return np.stack([np.array(c.saturated, bool) for c in block.channels], axis=1)


def assert_contiguous(blocks) -> None:
    firsts = [b.first_sample_index for b in blocks]
    lengths = [len(b.channels[0].field_t) for b in blocks]
    assert [a + n for a, n in zip(firsts, lengths)][:-1] == firsts[1:], "samples missing between blocks"
    assert np.all(np.diff([b.sequence for b in blocks]) == 1)


def test_a_cycle_streams_device_stamped_blocks_and_publishes_its_phases(start_driver, listen):
    start_driver(*QUICK_CYCLES)
    listen.ros.wait_for(lambda: listen.states and listen.blocks, "the first block and the present phase")
    assert listen.phases() == [Phase.IDLE]  # transient local: learned although it came before we listened
    request = RunCycle.Request(theta0_rad=0.6, repeats=2, tuning_steps=1, gap_s=0.1)
    response = listen.result(listen.call(listen.run_cycle, request))
    assert response.success, response.message
    assert response.ringdowns_recorded == 2 and response.cycle_id == 1
    assert 100.0 < response.excitation_frequency_hz < 125.0
    listen.ros.wait_for(lambda: listen.phases()[-1] == Phase.IDLE, "the cycle's last phase")
    E, R, G = Phase.EXCITING, Phase.RINGDOWN, Phase.GAP
    assert listen.phases(1) == [Phase.SETTLING, E, R, G, E, R, G, E, R, Phase.IDLE]
    states = [s for s in listen.states if s.cycle_id == 1]
    assert [s.tuning for s in states if s.phase == E] == [True, False, False]
    assert all(s.coils_on == (s.phase == E) and any(s.coil_current_amplitude_a) == s.coils_on for s in states)
    assert [s.repeat_index for s in states if s.phase == R] == [0, 0, 1]
    # Device stamps: one clock for all blocks (stamp − index/rate is the same), nothing lost.
    blocks = listen.blocks
    assert_contiguous(blocks)
    epochs = {stamps.nanoseconds(b.header.stamp) - round(b.first_sample_index * 1e9 / RATE_HZ) for b in blocks}
    assert len(epochs) == 1
    (epoch,) = epochs
    # Phases fall on samples of the same clock; each ring-down starts on a sample.
    assert all((stamps.nanoseconds(s.header.stamp) - epoch) % 50_000 == 0 for s in states)
    # Saturated samples are flagged and sit at the range limit; the coils saturate the sensors.
    flags = np.concatenate([saturated(b) for b in blocks])
    values = np.concatenate([field(b) for b in blocks])
    assert flags.any() and not flags.all()
    np.testing.assert_array_equal(np.abs(values[flags]), blocks[0].range_t)
    assert np.all(np.abs(values[~flags]) <= blocks[0].range_t)


def test_the_emergency_stop_ends_a_running_cycle_and_latches(start_driver, listen):
    start_driver(*QUICK_CYCLES)
    listen.ros.wait_for(lambda: listen.blocks, "the first block")
    cycle = listen.call(listen.run_cycle, RunCycle.Request(theta0_rad=0.0, repeats=3, tuning_steps=2, gap_s=1.0))
    listen.ros.wait_for(lambda: Phase.EXCITING in listen.phases(), "the excitation")
    stop = listen.result(listen.call(listen.estop, EmergencyStop.Request(engage=True, reason="test")))
    assert stop.success and stop.latched
    response = listen.result(cycle)  # the service answered the stop while the cycle ran
    assert not response.success and "emergency stop: test" in response.message
    listen.ros.wait_for(lambda: listen.phases()[-1] == Phase.FAULT, "the fault phase")
    assert not listen.states[-1].coils_on
    refused = listen.result(
        listen.call(listen.run_cycle, RunCycle.Request(theta0_rad=0.0, repeats=-1, tuning_steps=-1, gap_s=-1.0))
    )
    assert not refused.success and "emergency stop latched (test)" in refused.message
    release = listen.result(listen.call(listen.estop, EmergencyStop.Request(engage=False)))
    assert release.success and not release.latched
    listen.ros.wait_for(lambda: listen.phases()[-1] == Phase.IDLE, "idle again")
    listen.ros.wait_for(lambda: listen.diagnostics.get("estop_latched") == "False", "diagnostics of the release")


def test_parameters_out_of_range_are_rejected_with_their_reason(ros_context):
    node = driver.DriverNode()
    try:
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS, node.lifecycle_problem
        for name, value, why in [
            ("excitation_current_a", 10.5, "exceeds coil_current_cap_a=10.0"),
            ("repeats", 0, "repeats out of range"),
            ("excite_s", 11.0, "excite_s out of range"),
            ("max_duty_cycle", 0.0, "max_duty_cycle out of range"),
            ("record_path", "/tmp/x", "read-only"),
        ]:
            (result,) = node.set_parameters([Parameter(name, value=value)])
            assert not result.successful and why in result.reason, (name, result.reason)
        (result,) = node.set_parameters([Parameter("excite_s", value=0.2)])
        assert result.successful
        assert node.session.config.settings.excite_s == 0.2
    finally:
        node.destroy_node()


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["-p", "excitation_current_a:=12.0"], "excitation_current_a=12.0 exceeds coil_current_cap_a=10.0"),
        (["-p", "scenario:=no_such_scenario"], "scenario 'no_such_scenario' is neither"),
        (["-p", "backend:=serial"], "backend serial needs the device's port"),
        (["-p", "coil_setup:=helmholtz"], "does not drive the coils of scenario"),
        (
            ["-p", "scenario:=three_probes", "-p", "tracking:=true"],
            "tracking follows one probe; scenario 'three_probes'",
        ),
        (["-p", "record_path:=/"], "/ exists: a recording goes to a new path"),
        (["-p", "backend:=nidaqmx", "-p", "supply:=none"], "backend nidaqmx: NI-DAQmx (NI's driver runtime) is not"),
        (["-p", "backend:=nidaqmx", "-p", "supply:=scpi"], "supply scpi needs the supply's VISA address"),
        (["-p", "supply:=scpi"], "supply='scpi' goes with backend nidaqmx, not 'sim'"),
    ],
)
def test_a_bad_configuration_stops_the_driver_with_its_reason(arguments, message):
    run = subprocess.run(NODES[0].command(arguments), capture_output=True, text=True, timeout=120)
    assert run.returncode == EXIT_BAD_PARAMETER, run.stderr
    assert message in run.stderr and "Traceback" not in run.stderr


@pytest.mark.xdist_group("realtime")  # the device emulator's real-time threads
def test_the_serial_driver_streams_from_the_emulator_and_survives_an_unplug(start_driver, listen, tmp_path):
    with DeviceEmulator(SimulatedDevice(load_scenario()), tmp_path / "device") as emulator:
        driver_process = start_driver(
            "-p", "backend:=serial", "-p", f"serial_port:={emulator.link_path}", *QUICK_CYCLES
        )
        listen.ros.wait_for(lambda: len(listen.blocks) >= 20, "blocks from the emulated device")
        response = listen.result(
            listen.call(listen.run_cycle, RunCycle.Request(theta0_rad=1.0, repeats=1, tuning_steps=0, gap_s=0.0))
        )
        assert response.success, response.message
        ringdown = next(s for s in listen.states if s.phase == Phase.RINGDOWN)
        off_index = [index for index, on in emulator.device.coil_log if not on][-1]
        assert stamps.nanoseconds(ringdown.header.stamp) == emulator.clock.stamp_ns(off_index)
        emulator.unplug()
        listen.ros.wait_for(lambda: listen.diagnostics.get("link_up") == "False", "the driver to see the loss")
        assert listen.diagnostics["level"] == DiagnosticStatus.ERROR
        heard_before = len(listen.blocks)
        emulator.replug()
        listen.ros.wait_for(lambda: len(listen.blocks) > heard_before + 20, "blocks after the replug")
        listen.ros.wait_for(lambda: listen.diagnostics.get("connections") == "2", "diagnostics of the reconnection")
        assert driver_process.poll() is None
    assert listen.diagnostics["gaps"] == "1" and int(listen.diagnostics["missing_samples"]) > 0
    jump = [(a, b) for a, b in zip(listen.blocks, listen.blocks[1:]) if b.sequence != a.sequence + 1]
    ((before, after),) = jump
    missing = after.first_sample_index - (before.first_sample_index + len(before.channels[0].field_t))
    assert missing == int(listen.diagnostics["missing_samples"])


def read_blocks(path):
    return [m.message for m in bags.read_bag(path) if m.msgtype == "mows_msgs/msg/MagnetometerBlock"]


def test_a_recording_keeps_every_block_published_before_sigterm_and_replays(start_driver, listen, tmp_path):
    bag = tmp_path / "recording"
    recorder = start_driver("-p", f"record_path:={bag}")
    listen.ros.wait_for(lambda: len(listen.blocks) >= 40, "40 blocks")
    recorder.send_signal(signal.SIGTERM)
    listen.ros.wait_for(lambda: recorder.poll() is not None, "the driver to stop")
    assert recorder.returncode == 0, log(recorder)
    heard = {b.sequence for b in listen.blocks}
    recorded = read_blocks(bag)
    assert heard <= {b.sequence for b in recorded}
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["message_count"] >= len(recorded)
    assert_jazzy(bag)
    by_sequence = {b.sequence: b for b in recorded}
    for block in listen.blocks:
        np.testing.assert_array_equal(
            field(block), np.stack([c.field_t for c in by_sequence[block.sequence].channels], axis=1)
        )
    # The bag backend replays it through the same path, with the recorded device stamps.
    replayed = Listener(listen.ros)
    start_driver("-p", "backend:=bag", "-p", f"bag_path:={bag}", "-p", "bag_rate:=4.0", "-p", "bag_wait_subscribers:=1")
    last = recorded[-1].first_sample_index
    listen.ros.wait_for(lambda: replayed.blocks and replayed.blocks[-1].first_sample_index == last, "the replay")
    assert_contiguous(replayed.blocks)
    source = {b.first_sample_index: b for b in recorded}
    for block in replayed.blocks:
        original = source[block.first_sample_index]
        assert stamps.nanoseconds(block.header.stamp) == stamps.nanoseconds(original.header.stamp)
        np.testing.assert_array_equal(field(block), np.stack([c.field_t for c in original.channels], axis=1))
    listen.ros.wait_for(lambda: replayed.diagnostics.get("link") == "finished", "the end of the replay")
    # The recording holds the driver's start (IDLE, phase number 0) and no cycle: the replay's phase
    # (on a topic of its own, which a loaded host can deliver after the diagnostics).
    listen.ros.wait_for(lambda: replayed.states, "the replay's phase")
    assert [Phase(s.phase) for s in replayed.states] == [Phase.IDLE]
    assert replayed.diagnostics["phase"] == "IDLE"


def test_a_recording_killed_with_sigkill_is_repaired_and_replays(start_driver, listen, tmp_path, capsys):
    bag = tmp_path / "recording"
    mcap = bag / "recording.mcap"
    recorder = start_driver("-p", f"record_path:={bag}")
    listen.ros.wait_for(lambda: mcap.is_file() and mcap.stat().st_size > 2.5 * 2**20, "two chunks on disk")
    recorder.send_signal(signal.SIGKILL)  # no handler runs: whatever is in the driver's memory is lost
    listen.ros.wait_for(lambda: recorder.poll() is not None, "the driver to die")
    assert (bag / "metadata.yaml").is_file()  # written at the start
    with pytest.raises(bags.BagError, match="mows bag repair"):
        read_blocks(bag)
    assert cli.main(["bag", "repair", str(bag)]) == 0, capsys.readouterr().err
    assert "were recovered" in capsys.readouterr().out
    recorded = read_blocks(bag)
    assert len(recorded) >= 200  # two chunks of ~9 kB blocks
    # In publishing order, none twice (a gap the stream itself had under load stays a gap).
    assert np.all(np.diff([b.sequence for b in recorded]) > 0)
    by_sequence = {b.sequence: b for b in recorded}
    heard = [b for b in listen.blocks if b.sequence <= recorded[-1].sequence]
    assert heard and all(b.sequence in by_sequence for b in heard)
    for block in heard:
        np.testing.assert_array_equal(field(block), field(by_sequence[block.sequence]))
    replayed = Listener(listen.ros)
    start_driver("-p", "backend:=bag", "-p", f"bag_path:={bag}", "-p", "bag_rate:=8.0", "-p", "bag_wait_subscribers:=1")
    last = recorded[-1].first_sample_index
    listen.ros.wait_for(lambda: replayed.blocks and replayed.blocks[-1].first_sample_index == last, "the replay")
    # The replay is the recording, in order, from where this listener was matched: a block the
    # best-effort stream lost on the way (at 8× real time on a loaded machine) is a gap, never a
    # block out of order or one the recording does not hold.
    replayed_firsts = [b.first_sample_index for b in replayed.blocks]
    recorded_by_first = {b.first_sample_index: b for b in recorded}
    assert np.all(np.diff(replayed_firsts) > 0) and set(replayed_firsts) <= set(recorded_by_first)
    for block in replayed.blocks:
        np.testing.assert_array_equal(field(block), field(recorded_by_first[block.first_sample_index]))


def synthetic_bag(path, gap_after: int, gap_samples: int, rate_hz: float = RATE_HZ):
    """A bag of 30 blocks with ``gap_samples`` missing after block ``gap_after``, and two phases."""
    store = bags.typestore()
    Block, Channel = store.types["mows_msgs/msg/MagnetometerBlock"], store.types["mows_msgs/msg/MagnetometerChannel"]
    State, Header = store.types["mows_msgs/msg/ExcitationState"], store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]

    def header(index):
        return Header(Time(*divmod(1_000_000_000_000 + index * 50_000, 1_000_000_000)), "m")

    rng = np.random.default_rng(3)
    messages = []
    for k in range(30):
        index = k * BLOCK + (gap_samples if k > gap_after else 0)
        channels = [Channel(f"c{i}", rng.normal(0, 1e-6, BLOCK), rng.random(BLOCK) < 0.1) for i in range(2)]
        messages.append(
            bags.BagMessage(
                "/mows/raw",
                "mows_msgs/msg/MagnetometerBlock",
                k,
                Block(header(index), k, 0, index, rate_hz, 1e-5, 1e-10, channels),  # device_epoch 0
            )
        )
    for phase, index in [(Phase.EXCITING, 2000), (Phase.RINGDOWN, 4000)]:
        state = State(
            header(index),
            int(phase),
            phase.name,
            7,
            0,  # device_epoch
            0,
            1,
            False,
            phase == Phase.EXCITING,
            np.array([1.0, -1.0]) * (phase == Phase.EXCITING),
            112.0,
            0.5,
            0.2,
            "largest_spacing",
            np.zeros(0, np.uint8),
            np.zeros(0),
            np.zeros(0),
        )
        messages.append(bags.BagMessage("/mows/excitation", "mows_msgs/msg/ExcitationState", 100 + index, state))
    bags.write_bag(path, sorted(messages, key=lambda m: m.timestamp_ns))
    return [m.message for m in messages[:30]]


def test_the_bag_backend_replays_gaps_as_gaps(start_driver, listen, tmp_path):
    recorded = synthetic_bag(tmp_path / "synthetic", gap_after=14, gap_samples=1200)
    start_driver(
        "-p",
        "backend:=bag",
        "-p",
        f"bag_path:={tmp_path / 'synthetic'}",
        "-p",
        "bag_rate:=2.0",
        "-p",
        "bag_wait_subscribers:=1",
    )
    listen.ros.wait_for(
        lambda: listen.diagnostics.get("link") == "finished" and len(listen.blocks) >= 30, "the whole replay"
    )
    blocks = listen.blocks
    assert [b.first_sample_index for b in blocks] == [b.first_sample_index for b in recorded]
    assert [stamps.nanoseconds(b.header.stamp) for b in blocks] == [
        stamps.nanoseconds(b.header.stamp) for b in recorded
    ]
    jumps = np.diff([b.sequence for b in blocks])
    assert list(np.flatnonzero(jumps != 1)) == [14] and jumps[14] == 1 + 3  # 1200 samples: 3 blocks' worth
    for block, original in zip(blocks, recorded):
        np.testing.assert_array_equal(saturated(block), np.stack([c.saturated for c in original.channels], axis=1))
    assert (listen.diagnostics["gaps"], listen.diagnostics["missing_samples"]) == ("1", "1200")
    assert listen.diagnostics["phase"] == "RINGDOWN"  # the recording's, not the absent sequencer's
    assert [(Phase(s.phase), s.cycle_id) for s in listen.states] == [(Phase.EXCITING, 7), (Phase.RINGDOWN, 7)]
    assert [stamps.nanoseconds(s.header.stamp) for s in listen.states] == [
        1_000_000_000_000 + i * 50_000 for i in (2000, 4000)
    ]


def test_a_bag_without_a_sample_rate_stops_the_driver_with_its_reason(tmp_path):
    synthetic_bag(tmp_path / "rateless", gap_after=30, gap_samples=0, rate_hz=0.0)
    run = subprocess.run(
        NODES[0].command(["-p", "backend:=bag", "-p", f"bag_path:={tmp_path / 'rateless'}"]),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == EXIT_BAD_PARAMETER, run.stderr
    assert "sample rate 0.0 Hz" in run.stderr and "Traceback" not in run.stderr


# Long enough for every periodic part of the stream's path to come round several times: the
# achieved rate's 5 s window (reported from 5 s on: three windows), the diagnostics each second,
# 800 blocks of 25 ms. A longer stream goes through the same cycles again.
LIVE_STREAM_S = 20.0


@pytest.mark.slow
def test_a_live_stream_has_no_unexplained_gaps(start_driver, listen):
    start_driver()
    listen.ros.wait_for(lambda: listen.blocks, "the first block")
    first = listen.blocks[0].first_sample_index
    end = first + round(LIVE_STREAM_S * RATE_HZ)
    deadline = time.monotonic() + 180.0  # bound for a hang only: the stream takes LIVE_STREAM_S
    while listen.blocks[-1].first_sample_index + BLOCK < end:
        assert time.monotonic() < deadline, f"the stream did not deliver {LIVE_STREAM_S:g} s of samples"
        listen.ros.executor.spin_once(timeout_sec=0.1)
    listen.ros.wait_for(lambda: listen.diagnostics.get("samples", "0") != "0", "diagnostics")
    blocks = listen.blocks
    print(
        f"{LIVE_STREAM_S:g} s stream: {len(blocks)} blocks, sequences {blocks[0].sequence}…{blocks[-1].sequence}, "
        f"driver gaps {listen.diagnostics['gaps']}, achieved rate {listen.diagnostics['achieved_sample_rate_hz']}"
    )
    assert len(blocks) >= LIVE_STREAM_S * RATE_HZ / BLOCK
    assert_contiguous(blocks)
    assert listen.diagnostics["gaps"] == "0" and listen.diagnostics["missing_samples"] == "0"


def test_docs_list_every_parameter_topic_and_service():
    text = (Path(__file__).parents[2] / "docs" / "nodes.md").read_text()
    names = [spec.name for spec in driver.PARAMETERS]
    names += [
        f"/{outputs.RAW_TOPIC}",
        f"/{outputs.EXCITATION_TOPIC}",
        f"/{outputs.JOINT_STATES_TOPIC}",
    ]
    names += [  # node-private: /driver/… in the root namespace
        name.replace("~", f"/{driver.NODE_NAME}")
        for name in (
            services.MEASUREMENT_CYCLE_ACTION,
            services.RUN_CYCLE_SERVICE,
            services.EMERGENCY_STOP_SERVICE,
            services.SET_FIELD_CURRENT_SERVICE,
        )
    ]
    assert [name for name in names if f"`{name}`" not in text] == []


def test_a_negative_current_on_a_unipolar_supply_is_refused_naming_it_and_the_range(start_driver, listen, tmp_path):
    scenario = tmp_path / "unipolar.yaml"
    scenario.write_text("extends: calibration\nsupply: {polarity: unipolar}\n")
    start_driver("-p", f"scenario:={scenario}", "-p", "coil_setup:=helmholtz")
    listen.ros.wait_for(lambda: listen.blocks, "the first block")
    supply = listen.ros.node.create_client(SetFieldCurrent, "/driver/set_field_current")
    refused = listen.result(listen.call(supply, SetFieldCurrent.Request(current_a=-0.5)))
    assert not refused.success and (refused.min_current_a, refused.max_current_a) == (0.0, 2.0)
    assert refused.message == (
        "supply current refused: supply current -0.5 A is outside the supply's range 0 … +2 A (unipolar) "
        "(refused, never sent)"
    )
    listen.ros.wait_for(lambda: "supply_current_a" in listen.diagnostics, "the supply on /diagnostics")
    assert listen.diagnostics["supply_current_a"] == "0.0"  # never ramped


def test_the_supply_ramps_on_request_is_capped_and_the_emergency_stop_zeroes_it(start_driver, listen):
    start_driver("-p", "scenario:=calibration", "-p", "coil_setup:=helmholtz", "-p", "supply_current_cap_a:=1.5")
    listen.ros.wait_for(lambda: listen.blocks, "the first block")
    supply = listen.ros.node.create_client(SetFieldCurrent, "/driver/set_field_current")
    response = listen.result(listen.call(supply, SetFieldCurrent.Request(current_a=1.0)))
    assert response.success and response.current_a == 1.0, response.message
    assert response.reached_sample_index > 0.49 * RATE_HZ  # 1 A at 2 A/s in 10 ms steps: ≥ 0.49 s of ramp
    assert (response.min_current_a, response.max_current_a) == (-1.5, 1.5)  # the scenario's supply is bipolar
    listen.ros.wait_for(lambda: listen.diagnostics.get("supply_current_a") == "1.0", "the supply on /diagnostics")
    refused = listen.result(listen.call(supply, SetFieldCurrent.Request(current_a=1.6)))
    assert not refused.success and "supply_current_cap_a" in refused.message
    stop = listen.result(listen.call(listen.estop, EmergencyStop.Request(engage=True, reason="test")))
    assert stop.success
    listen.ros.wait_for(lambda: listen.diagnostics.get("supply_current_a") == "0.0", "the supply back at zero")


def test_the_bench_backend_opens_the_scpi_supply_under_the_driver_s_lower_cap():
    """``supply_current_cap_a`` below the supply file's cap: the supply's limits (and the
    instrument's own safety limit) are the lower cap; closing leaves it at zero, output off."""
    from mows.device.backends.factory import make_backend
    from mows.device.instruments.scpi import SIMULATED_RESOURCE, SIMULATED_SUPPLY_FILE
    from mows.device.simulated.daqmx_card import SimulatedCard
    from mows.physics.coils import CurrentCap
    from mows_driver.parameters import backend_settings

    values = {
        **{spec.name: spec.default for spec in driver.PARAMETERS},
        "backend": "nidaqmx",
        "supply": "scpi",
        "supply_resource": SIMULATED_RESOURCE,
        "visa_library": f"{SIMULATED_SUPPLY_FILE}@sim",
        "supply_current_cap_a": 1.0,
    }
    with SimulatedCard(SimulatedDevice(load_scenario("calibration"))).installed():
        backend = make_backend(backend_settings(values), CurrentCap(10.0))  # as the driver's configure
        try:
            assert backend.supply_limits.cap_a == 1.0
            properties = backend.supply.resource.visalib.devices[SIMULATED_RESOURCE]._properties
            assert properties["current_safety_limit"].get_value() == 1.0
        finally:
            backend.close()
    assert (properties["current"].get_value(), properties["output"].get_value()) == (0.0, 0)
