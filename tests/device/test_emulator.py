"""The serial link end to end, with no hardware: the device emulator on a pty, the serial
client and backend, and the driver session over them.

Safety deadline (the only timing asserted): the watchdog switches the coils off within 200 ms
of the driver's last frame. It is measured on the device's own sample clock: from the sample
at which the emulator read the last host frame to the first sample with the coils off in the
device's own coil log (taken from the samples' coil flags). The emulator reads host frames
once per loop, so the arrival stamp may be up to one Samples frame (FRAME_S = 10 ms) late:
the assertion leaves that tolerance, latency ≤ 200 ms − FRAME_S.
"""

import contextlib
import math
import time

import pytest

from device.spy import SpyDevice
from mows.device.backends.serial_backend import SerialBackend
from mows.device.cycle.phases import CycleRequest, CycleSettings, Phase
from mows.device.interface import CoilCommand, CoilTone, FieldCurrentCommand, LinkEvent
from mows.device.protocol.payloads import Ack, Coils, FieldCurrent, Samples, Status
from mows.device.serial.emulator import FRAME_S, DeviceEmulator
from mows.device.serial.link import SerialLink
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

WAIT_S = 60.0  # bound for a test that hangs; each wait ends as soon as its condition holds
WATCHDOG_BOUND_S = 0.2
CAP_A = 10.0
SCENARIO = load_scenario()
# Real-time threads: never beside the graph-sized tests (pyproject.toml, addopts).
pytestmark = pytest.mark.xdist_group("realtime")


def wait_for(condition, what, step=lambda: time.sleep(0.01)):
    deadline = time.monotonic() + WAIT_S
    while not (value := condition()):
        if time.monotonic() > deadline:
            raise AssertionError(f"gave up after {WAIT_S} s waiting for {what}")
        step()
    return value


@pytest.fixture
def emulator(tmp_path):
    with DeviceEmulator(SpyDevice(SCENARIO), tmp_path / "mows-device", CurrentCap(CAP_A)) as emulator:
        yield emulator


@pytest.fixture
def link(emulator):
    link = SerialLink(str(emulator.link_path)).start()
    yield link
    link.close()


@pytest.fixture
def session(link):
    backend = SerialBackend(link, CurrentCap(CAP_A))
    settings = CycleSettings(excite_s=0.3, ringdown_s=0.3, gap_s=0.1, repeats=1, tuning_steps=1, turn_settle_s=0.1)
    config = SessionConfig(0.025, settings, SCENARIO.setup, CurrentCap(CAP_A), 110.0, fit_tuning)
    session = DeviceSession(backend, config, armed=True)
    yield session
    session.close()


def collect(link, what, enough):
    """Poll ``link`` until ``enough(items)``; every item received."""
    items = []
    wait_for(lambda: enough(items), what, lambda: items.extend(link.poll(0.05)))
    return items


def samples_of(items):
    return [item for item in items if not isinstance(item, LinkEvent) and isinstance(item.body, Samples)]


def test_the_device_streams_contiguous_samples_on_its_own_clock(emulator, link):
    items = collect(link, "50 Samples frames", lambda items: len(samples_of(items)) >= 50)
    # The device streams from power-on, so frames it sent before it answered Hello can come
    # ahead of the link's up event (on a loaded host the link opens late): one up, no down.
    events = [item for item in items if isinstance(item, LinkEvent)]
    assert len(events) == 1 and events[0].up
    assert link.info == emulator.info
    frames = samples_of(items)
    firsts = [f.body.first_sample_index for f in frames]
    assert firsts == list(range(firsts[0], firsts[0] + 200 * len(frames), 200))
    assert all(f.timestamp_ns == emulator.clock.stamp_ns(f.body.first_sample_index) for f in frames)
    assert all(f.body.counts.shape == (200, 2) for f in frames)
    assert link.lost_frames == 0 and link.decoder.rejected_total == 0


def test_commands_above_the_cap_never_reach_the_device(emulator, link):
    backend = SerialBackend(link, CurrentCap(CAP_A))
    collect(link, "the device to answer", lambda items: link.up)
    with pytest.raises(ValueError, match="exceeds the cap"):
        backend.send(CoilCommand(1, 0, (CoilTone(0, 110.0, (CAP_A * 1.001, 0.0)),)))
    # Past the driver's check, straight onto the wire: the device refuses them itself.
    refused = {
        link.send(Coils(0, 0, 110.0, (0.0, -CAP_A * 1.5))): Ack.REFUSED_OVER_CAP,
        link.send(Coils(Coils.IMMEDIATE, 0, 110.0, (math.nan, 1.0))): Ack.REFUSED_INVALID,
        link.send(Coils(0, 0, 110.0, (1.0, 1.0, 1.0))): Ack.REFUSED_INVALID,
    }
    accepted = link.send(Coils(0, 0, 110.0, (CAP_A, -CAP_A)))  # at the cap is allowed

    def acks(items):
        return {
            i.body.command_sequence: i.body for i in items if not isinstance(i, LinkEvent) and isinstance(i.body, Ack)
        }

    answers = acks(collect(link, "four acks", lambda items: len(acks(items)) == 4))
    assert {sequence: answers[sequence].result for sequence in refused} == refused
    assert answers[accepted].accepted
    wait_for(lambda: len(emulator.device.device.drives) == 1, "the accepted drive to apply")
    assert [list(d) for d in emulator.device.device.drives] == [[CAP_A, -CAP_A]]


def test_the_watchdog_switches_the_coils_off_when_the_driver_is_lost(emulator, link):
    backend = SerialBackend(link, CurrentCap(CAP_A))
    collect(link, "the device to answer", lambda items: link.up)
    backend.send(CoilCommand(1, 0, (CoilTone(0, 110.0, (1.0, -1.0)),)))
    collect(link, "the coils to go on", lambda items: emulator.device.coils_on)
    link.close()  # the driver is gone: no heartbeat, no frame
    wait_for(lambda: emulator.watchdog_trips, "the watchdog")
    wait_for(lambda: not emulator.device.coils_on, "the coils to go off")
    ((last_host_index, off_index),) = emulator.watchdog_trips
    on_log = list(emulator.device.coil_log)
    assert on_log[-1] == (off_index, False) and on_log[-2][1]
    latency_s = (off_index - last_host_index) / emulator.info.sample_rate_hz
    assert latency_s <= WATCHDOG_BOUND_S - FRAME_S
    assert emulator.status().watchdog_trips == 1


def test_heartbeats_keep_the_coils_on(emulator, link):
    backend = SerialBackend(link, CurrentCap(CAP_A))
    collect(link, "the device to answer", lambda items: link.up)
    backend.send(CoilCommand(1, 0, (CoilTone(0, 110.0, (1.0, -1.0)),)))
    items = collect(
        link,
        "1 s of device time with the coils on",
        lambda items: sum(len(f.body.counts) for f in samples_of(items)) >= 20_000,
    )
    statuses = [i.body for i in items if not isinstance(i, LinkEvent) and isinstance(i.body, Status)]
    # On a starved machine a heartbeat can be late, and then a trip is right; what must hold is
    # that the device trips only after the host fell silent for the watchdog time (on the
    # device's clock), at exactly that time, and that without such a silence the coils stay on.
    silences = {start for start, _ in emulator.long_silences}
    if (ongoing := emulator.silent_since()) is not None:
        silences.add(ongoing)
    watchdog_samples = round(emulator.info.watchdog_timeout_s * emulator.info.sample_rate_hz)
    assert all(last in silences and off - last == watchdog_samples for last, off in emulator.watchdog_trips)
    if not silences:
        assert statuses[-1].coils_on and emulator.watchdog_trips == []


def step_until(session, condition, what, blocks=None, events=None):
    """Step ``session`` until ``condition()``; its blocks and events go to the lists given."""
    blocks, events = ([] if blocks is None else blocks), ([] if events is None else events)

    def step():
        output = session.step(0.05)
        blocks.extend(output.blocks)
        events.extend(output.events)

    wait_for(condition, what, step)
    return blocks, events


def jumps(blocks):
    """(block before, block after) of every discontinuity of the sample index."""
    return [(a, b) for a, b in zip(blocks, blocks[1:]) if a.first_sample_index + len(a) != b.first_sample_index]


def test_a_cycle_over_the_link_stamps_the_ringdown_at_the_device_switch_off(emulator, session):
    step_until(session, lambda: session.health().get("samples", 0) > 0, "samples")
    done = []
    session.start_cycle(CycleRequest(0.4), done.append)
    _, events = step_until(session, lambda: done, "the cycle to end")
    assert done[0].success, done[0].message
    switches = [
        (e.sample_index, e.phase == Phase.EXCITING) for e in events if e.phase in (Phase.EXCITING, Phase.RINGDOWN)
    ]
    assert switches == list(emulator.device.coil_log)
    assert all(e.stamp_ns == emulator.clock.stamp_ns(e.sample_index) for e in events)


ATTEMPTS = 5  # fresh devices for the watchdog-mid-cycle test; see cycle_with_coils_on


def cycle_with_coils_on(tmp_path, attempt, stack):
    """(emulator, session, done, events) with a cycle whose coils the device has switched on.

    On a starved machine the cycle can fail before that (this thread stalls past the watchdog
    while settling, or a command reaches the device after its sample): the cycle then ends,
    correctly, before the test can hang the driver mid-excitation. Such an attempt yields None
    with its reason, and the caller starts over on a fresh device."""
    emulator = stack.enter_context(
        DeviceEmulator(SpyDevice(SCENARIO), tmp_path / f"mows-device-{attempt}", CurrentCap(CAP_A))
    )
    link = SerialLink(str(emulator.link_path)).start()
    stack.callback(link.close)
    settings = CycleSettings(excite_s=2.0, ringdown_s=0.3, repeats=1, tuning_steps=0, turn_settle_s=0.1)
    session = DeviceSession(
        SerialBackend(link, CurrentCap(CAP_A)),
        SessionConfig(0.025, settings, SCENARIO.setup, CurrentCap(CAP_A), 110.0, fit_tuning),
        armed=True,
    )
    step_until(session, lambda: session.health().get("samples", 0) > 0, "samples")
    done = []
    session.start_cycle(CycleRequest(0.4), done.append)
    # From the device's coil log, not its present state: on a loaded machine this thread can
    # stall past the watchdog on its own, and the coils are off again before the next look.
    coils_on = lambda: any(on for _, on in emulator.device.coil_log)  # noqa: E731
    _, events = step_until(session, lambda: coils_on() or done, "the coils to go on or the cycle to end")
    if not coils_on():
        return None, done[0].message
    return (emulator, session, done, events), ""


def test_a_watchdog_trip_during_a_cycle_fails_it_instead_of_announcing_a_ringdown(tmp_path):
    early_failures = []
    with contextlib.ExitStack() as stack:
        for attempt in range(ATTEMPTS):
            started, reason = cycle_with_coils_on(tmp_path, attempt, stack)
            if started is not None:
                break
            early_failures.append(reason)
        assert started is not None, f"every cycle failed before its coils went on: {early_failures}"
        emulator, session, done, events = started
        time.sleep(0.5)  # the driver hangs: no heartbeat for longer than the watchdog allows
        step_until(session, lambda: done, "the cycle to end", events=events)
        assert not done[0].success and "watchdog" in done[0].message
        ((_, off_index),) = emulator.watchdog_trips
        # No RINGDOWN: the cycle's phases end with its FAULT.
        assert [e.phase for e in events if e.cycle_id == 1] == [Phase.SETTLING, Phase.EXCITING, Phase.FAULT]
        assert events[-1].phase == Phase.FAULT and "watchdog" in events[-1].reason
        assert list(emulator.device.coil_log)[-1] == (off_index, False)
        assert session.health()["device_faults"] == 1


def test_unplugging_leads_to_reconnection_with_backoff_and_a_reported_gap(emulator, link, session):
    blocks, _ = step_until(session, lambda: session.health().get("samples", 0) >= 2000, "samples")
    emulator.unplug()
    step_until(session, lambda: not session.link_up, "the link to go down", blocks)
    step_until(session, lambda: len(link.retry_delays_s) >= 5, "five attempts to reopen", blocks)
    emulator.replug()
    step_until(
        session,
        lambda: session.link_up and jumps(blocks) and blocks[-1] is not jumps(blocks)[0][0],
        "blocks from after the gap",
        blocks,
    )
    # Back-off doubles from 50 ms, starting over once the device is back.
    delays = link.retry_delays_s
    assert delays[:5] == [0.05, 0.1, 0.2, 0.4, 0.8]
    assert all(later == min(2 * earlier, 2.0) for earlier, later in zip(delays, delays[1:]))
    health = session.health()
    assert (health["connections"], health["link_changes"], health["gaps"]) == (2, 3, 1)
    assert health["lost_frames"] > 0 and health["missing_samples"] > 0
    # The gap is in the blocks: the one before it may be short, the sequence jumps after it.
    ((before, after),) = jumps(blocks)
    assert after.first_sample_index - before.end_index == health["missing_samples"]
    assert after.sequence - before.sequence >= 2
    assert all(b.sequence == a.sequence + 1 for a, b in zip(blocks, blocks[1:]) if (a, b) != (before, after))


# --- the static-field supply ---------------------------------------------------------------------
@pytest.fixture
def supplied(tmp_path):
    """An emulated calibration bench: the Pasco pair on a 2 A supply (2 A/s)."""
    with DeviceEmulator(SimulatedDevice(load_scenario("calibration")), tmp_path / "bench", CurrentCap(CAP_A)) as bench:
        link = SerialLink(str(bench.link_path)).start()
        yield bench, link
        link.close()


def acks_of(items):
    return {i.body.command_sequence: i.body for i in items if not isinstance(i, LinkEvent) and isinstance(i.body, Ack)}


def test_the_supply_ramps_on_a_framed_command_and_the_device_acks_where_the_ramp_ends(supplied):
    bench, link = supplied
    collect(link, "the stream to run", lambda items: len(samples_of(items)) >= 20)
    over = link.send(FieldCurrent(0, 0, 2.5))
    ramp = link.send(FieldCurrent(0, 0, 1.0))
    answers = acks_of(collect(link, "two acks", lambda items: len(acks_of(items)) == 2))
    assert answers[over].result == Ack.REFUSED_OVER_CAP
    assert answers[ramp].accepted
    # polling sends the heartbeats: without them the watchdog would ramp the supply back down
    wait_for(lambda: bench.device.device.field_current_a == 1.0, "the ramp to arrive", lambda: link.poll(0.02))
    assert not bench.watchdog_trips
    # the ramp's 50 steps of 10 mA every 10 ms: it arrives 0.49 s after it starts, where the ack said
    assert bench.device.next_index > answers[ramp].applied_sample_index


def test_a_driver_lost_mid_calibration_leaves_the_supply_at_zero(supplied):
    """A killed driver (SIGKILL) runs no code of its own: only the device can bring its supply
    down, so this is a test of the device's watchdog, the link cut mid-ramp. The simulated
    device lives inside the driver's process and dies with it, leaving no supply to be at zero;
    the sim path's graceful endings (close on SIGINT/SIGTERM, the emergency stop, a cancel) are
    tested on the session (tests/device/test_cycle.py)."""
    bench, link = supplied
    backend = SerialBackend(link, CurrentCap(CAP_A))
    collect(link, "the stream to run", lambda items: len(samples_of(items)) >= 20)
    backend.send(FieldCurrentCommand(1, 0, 1.5))
    wait_for(lambda: bench.device.device.field_current_a >= 0.5, "the supply to ramp up", lambda: link.poll(0.02))
    link.close()  # the driver is gone mid-ramp: no heartbeat, no frame
    wait_for(lambda: bench.watchdog_trips, "the watchdog")
    wait_for(lambda: bench.device.device.field_current_a == 0.0, "the supply to ramp down")
    assert bench.device.supply_target_a == 0.0
