"""A session replaying a recording (the bag backend) has no sequencer: the phase it reports is
the one of the recording's last replayed excitation state; the supply's recorded states and
the probes a multi-tone excitation rang come back as they were recorded."""

import numpy as np

from mows.device.backends.bag_backend import BagBackend
from mows.device.cycle.phases import CycleSettings, Phase
from mows.device.recording import bags
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import PRESETS, CurrentCap

RATE_HZ, BLOCK = 20_000.0, 500
# The probes a recorded excitation and its ring-down list: ids, tones, θ0s.
PROBES = ((0, 2), (100.0, 125.0), (0.3, 1.7))


def recording(path, phases=((1, Phase.EXCITING), (2, Phase.RINGDOWN))):
    """Four blocks, with an excitation state for each (block number, phase) of ``phases``."""
    store = bags.typestore()
    Block, Channel = store.types["mows_msgs/msg/MagnetometerBlock"], store.types["mows_msgs/msg/MagnetometerChannel"]
    State, Header = store.types["mows_msgs/msg/ExcitationState"], store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]

    def header(index):
        return Header(Time(*divmod(10**12 + index * 50_000, 10**9)), "m")

    messages = [
        bags.BagMessage(
            "/mows/raw",
            "mows_msgs/msg/MagnetometerBlock",
            2 * k,
            Block(
                header(k * BLOCK),
                k,
                0,  # device_epoch
                k * BLOCK,
                RATE_HZ,
                1e-5,
                1e-10,
                [Channel("c", np.zeros(BLOCK), np.zeros(BLOCK, bool))],
            ),
        )
        for k in range(4)
    ]
    for k, phase in phases:
        state = State(
            header(k * BLOCK),
            int(phase),
            phase.name,
            1,
            0,  # device_epoch
            0,
            1,
            False,
            phase == Phase.EXCITING,
            np.zeros(2),
            112.0,
            0.0,
            0.02,
            "largest_spacing",
            *(
                np.array(values, dtype)
                for values, dtype in zip(
                    PROBES if phase in (Phase.EXCITING, Phase.RINGDOWN) else ((), (), ()), (np.uint8, float, float)
                )
            ),
        )
        messages.append(bags.BagMessage("/mows/excitation", "mows_msgs/msg/ExcitationState", 2 * k + 1, state))
    Supply = store.types["mows_msgs/msg/SupplyState"]
    for k, ramping in [(1, True), (3, False)]:
        supply = Supply(header(k * BLOCK + 7), 1.5, ramping, k * BLOCK + 7, "")
        messages.append(bags.BagMessage("/mows/supply", "mows_msgs/msg/SupplyState", 2 * k + 1, supply))
    bags.write_bag(path, sorted(messages, key=lambda m: m.timestamp_ns))


def replaying(path) -> DeviceSession:
    cap = CurrentCap(10.0)
    config = SessionConfig(
        0.025, CycleSettings(), PRESETS["largest_spacing"](current_limit_a=cap.limit_a), cap, 110.0, fit_tuning
    )
    return DeviceSession(BagBackend(path, rate=100.0), config)


def test_the_replayed_phase_is_the_recordings(tmp_path):
    recording(tmp_path / "bag")
    session = replaying(tmp_path / "bag")
    assert session.health()["phase"] == "none replayed yet"
    phases, probes, supply = [], [], []
    while session.health()["link"] != "finished":
        output = session.step(0.05)
        phases += [e.phase for e in output.events]
        probes += [(e.probe_ids, e.probe_frequency_hz, e.probe_theta0_rad) for e in output.events]
        supply += output.supply
        if output.events:
            assert session.health()["phase"] == output.events[-1].phase.name
    assert phases == [Phase.EXCITING, Phase.RINGDOWN] and session.health()["phase"] == "RINGDOWN"
    assert probes == [PROBES, PROBES]
    # the supply's ramp and its end come back as recorded: what a replaying driver republishes
    assert [(e.sample_index, e.current_a, e.ramping) for e in supply] == [(507, 1.5, True), (1507, 1.5, False)]
    assert supply[1].stamp_ns == 10**12 + 1507 * 50_000 and session.health()["supply_state_a"] == 1.5
    session.close()


def test_a_recording_that_ends_idle_reports_idle(tmp_path):
    """A driver's recording opens with the IDLE of its start and returns to IDLE after every
    cycle; IDLE is phase number 0, and the replay still reports it as the recording's phase."""
    recording(tmp_path / "bag", [(0, Phase.IDLE), (1, Phase.EXCITING), (2, Phase.RINGDOWN), (3, Phase.IDLE)])
    session = replaying(tmp_path / "bag")
    phases = []
    while session.health()["link"] != "finished":
        phases += [e.phase for e in session.step(0.05).events]
    assert phases == [Phase.IDLE, Phase.EXCITING, Phase.RINGDOWN, Phase.IDLE]
    assert session.health()["phase"] == "IDLE"
    session.close()
