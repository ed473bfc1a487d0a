"""The measurement-cycle sequencer on the simulated device (unpaced: as fast as it computes):
order of phases, tuning to the resonance, ring-down stamps exact to the sample, the
duty-cycle limit, the emergency-stop latch, and the coil current cap (property tests)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from device.spy import SpyDevice
from mows.device.backends.sim_backend import SimBackend
from mows.device.cycle.phases import CycleRequest, CycleSettings, Phase
from mows.device.cycle.sequencer import CycleSequencer
from mows.device.interface import CoilCommand, CoilTone, CommandResult
from mows.device.simulated.scheduled import ScheduledDevice
from mows.device.stream.device_time import DeviceTimeLoop, scheduled_device
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import CurrentCap, helmholtz, largest_spacing
from mows.physics.coupling import PlacedProbe
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE
from mows.records.samples import SampleBlock
from mows.sim.scenario import Scenario, load_scenario
from mows.sim.simulator import SimulatedDevice

CAP_A = 10.0
FAST = CycleSettings(excite_s=0.5, ringdown_s=0.5, gap_s=0.2, repeats=2, tuning_steps=2, turn_settle_s=0.2)
ONE = (PlacedProbe(PAPER_PROBE, Pose()),)  # the paper's probe at the coils' centre, alone on its stage
MAX_STEPS = 100_000  # bound for a cycle that never ends (a bug), not a timing


def session_on_simulator(cycle_settings=FAST, frequency_hz=110.0, cap_a=CAP_A):
    scenario = load_scenario()
    backend = SimBackend(SimulatedDevice(scenario), CurrentCap(cap_a), paced=False)
    return DeviceSession(
        backend,
        SessionConfig(0.025, cycle_settings, scenario.setup, CurrentCap(cap_a), frequency_hz, fit_tuning),
        armed=True,
    )


def run(session, request=CycleRequest(0.3), until=None):
    """Start a cycle and step until it ends, or until ``until(events)`` holds; returns the
    list the outcome goes to (empty while the cycle runs) and the phase events."""
    events, done = [], []
    events += session.step(0.0).events
    session.start_cycle(request, done.append)
    for _ in range(MAX_STEPS):
        if done or (until is not None and until(events)):
            return done, events
        events += session.step(0.0).events
    raise AssertionError("the cycle did not end")


def coil_log(session):
    return list(session.backend.device.coil_log)


def test_a_cycle_goes_through_its_phases_in_order():
    session = session_on_simulator()
    (outcome,), events = run(session)
    assert outcome.success, outcome.message
    cycle = [e for e in events if e.cycle_id == outcome.cycle_id]
    T, R = True, False
    # Two tuning ring-downs, then the two recorded ones; each kick but the first after a gap.
    kicks = [(T, 0), (T, 1), (R, 0), (R, 1)]
    phases = [[(Phase.GAP, *k)] * (i > 0) + [(Phase.EXCITING, *k), (Phase.RINGDOWN, *k)] for i, k in enumerate(kicks)]
    assert [(e.phase, e.tuning, e.repeat_index) for e in cycle] == [
        (Phase.SETTLING, R, 0),
        *(phase for kick in phases for phase in kick),
        (Phase.IDLE, R, 0),
    ]
    assert all(e.coils_on == (e.phase == Phase.EXCITING) for e in events)
    assert all(any(e.currents_a) == e.coils_on for e in events)
    assert [e.sample_index for e in cycle] == sorted(e.sample_index for e in cycle)
    assert outcome.ringdowns_recorded == 2
    assert session.sequencer.phase == Phase.IDLE and not session.backend.device.coils_on


def test_the_excitation_follows_the_setup_current_scheme():
    session = session_on_simulator()
    theta0 = 2.2
    _, events = run(session, CycleRequest(theta0))
    expected = largest_spacing().currents_a(theta0, FAST.excitation_current_a)
    for event in (e for e in events if e.phase == Phase.EXCITING):
        np.testing.assert_allclose(event.currents_a, expected)
        assert event.theta0_rad == theta0


def test_tuning_converges_to_the_resonance():
    start_hz = 107.0  # 5 % below the probe's resonance: the drive is far off it
    session = session_on_simulator(frequency_hz=start_hz)
    (outcome,), events = run(session)
    truth_hz = session.backend.device.device.expected_frequencies_hz()[0]
    assert abs(start_hz - truth_hz) > 5.0
    assert [fit.ok for fit in outcome.tuning_fits] == [True, True]
    # The tuned frequency is the fitted ring-down frequency: within 10 mHz of the truth.
    assert outcome.frequency_hz == pytest.approx(truth_hz, abs=0.01)
    recorded = [e for e in events if e.phase == Phase.EXCITING and not e.tuning]
    assert all(e.frequency_hz == outcome.frequency_hz for e in recorded)


def test_ringdown_stamps_are_the_samples_where_the_coils_went_off():
    session = session_on_simulator()
    (outcome,), events = run(session)
    clock = session.backend.clock
    switches = [
        (e.sample_index, e.phase == Phase.EXCITING) for e in events if e.phase in (Phase.EXCITING, Phase.RINGDOWN)
    ]
    # The device's own record of its coils (from the samples' coil flags) agrees exactly.
    assert switches == coil_log(session)
    assert all(e.stamp_ns == clock.stamp_ns(e.sample_index) for e in events)
    ringdowns = [e for e in events if e.phase == Phase.RINGDOWN]
    assert all(e.planned_duration_s == FAST.ringdown_s for e in ringdowns)


def test_the_duty_cycle_limit_stretches_the_gaps():
    limited = CycleSettings(
        excite_s=0.5,
        ringdown_s=0.2,
        gap_s=0.0,
        repeats=3,
        tuning_steps=0,
        turn_settle_s=0.2,
        max_duty_cycle=0.3,
        duty_window_s=2.0,
    )
    session = session_on_simulator(limited)
    (outcome,), events = run(session)
    assert outcome.success, outcome.message
    rate = session.backend.device.device.sample_rate_hz
    log = coil_log(session)
    intervals = list(zip([i for i, on in log if on], [i for i, on in log if not on]))
    assert len(intervals) == 3
    window = round(limited.duty_window_s * rate)
    for _, off in intervals:  # the fullest windows end where the coils go off
        on_samples = sum(max(0, min(b, off) - max(a, off - window)) for a, b in intervals)
        assert on_samples <= limited.max_duty_cycle * window
    gaps = [e for e in events if e.phase == Phase.GAP]
    assert len(gaps) == 2 and all(g.planned_duration_s > 0.0 for g in gaps)


def test_an_excitation_longer_than_the_duty_budget_is_refused():
    session = session_on_simulator(CycleSettings(excite_s=0.7, max_duty_cycle=0.3, duty_window_s=2.0))
    session.step(0.0)
    with pytest.raises(ValueError, match="duty-cycle limit"):
        session.start_cycle(CycleRequest(0.0), print)
    assert coil_log(session) == []


def test_an_excitation_stopped_before_its_answers_counts_towards_the_duty_limit():
    # A device that answers late (a serial link) may have switched the coils on at the commanded
    # sample: a stop before its answers counts the samples from there up to the stop.
    rate = 1000.0
    quick = CycleSettings(excite_s=0.1, ringdown_s=0.1, repeats=1, tuning_steps=0, turn_settle_s=0.0, duty_window_s=1.0)
    sequencer = CycleSequencer(quick, largest_spacing(), CurrentCap(CAP_A), rate, 110.0, fit=fit_tuning, probes=ONE)

    def samples(first, n):
        return SampleBlock(first, round(first * 1e9 / rate), rate, np.zeros((n, 2)), np.zeros((n, 2), bool))

    sequencer.on_samples(samples(0, 1))
    (turn,) = sequencer.start(CycleRequest(0.3)).commands
    sequencer.on_result(CommandResult(turn.command_id, True, turn.at_sample_index))
    on, off = sequencer.on_samples(samples(1, 10)).commands
    assert isinstance(on, CoilCommand) and not on.off and off.off
    sequencer.on_samples(samples(11, on.at_sample_index + 50 - 11))  # no answer yet
    assert sequencer.duty_fraction() == 0.0
    assert sequencer.emergency_stop("operator").coils_off_now
    assert sequencer.duty_fraction() * round(quick.duty_window_s * rate) == pytest.approx(50)


def test_the_emergency_stop_switches_off_at_once_and_latches():
    session = session_on_simulator()
    done, _ = run(session, until=lambda events: any(e.phase == Phase.EXCITING for e in events))
    assert not done and session.backend.device.coils_on
    stop_index = session.backend.device.next_index
    assert session.emergency_stop(True, "operator")
    events = session.step(0.0).events
    # The coils are off from the device's very next sample, and what was scheduled is gone.
    assert coil_log(session)[-1] == (stop_index, False)
    assert [(e.phase, e.reason, e.sample_index) for e in events] == [
        (Phase.FAULT, "emergency stop: operator", stop_index)
    ]
    assert not done[0].success and "emergency stop" in done[0].message
    with pytest.raises(ValueError, match="emergency stop latched"):
        session.start_cycle(CycleRequest(0.0), print)
    for _ in range(200):  # 2 s of samples: the coils stay off while latched
        session.step(0.0)
    assert coil_log(session)[-1] == (stop_index, False)
    assert not session.emergency_stop(False, "")
    assert [e.phase for e in session.step(0.0).events] == [Phase.IDLE]
    (outcome,), _ = run(session)
    assert outcome.success


def test_a_cancel_or_a_disarm_switches_off_at_once_and_is_no_fault():
    """Nobody waits for the cycle any more (its client left, the driver was deactivated): the
    coils go off at the next sample, the cycle fails as cancelled, and the sequencer is IDLE,
    with no fault reported; the next cycle runs."""
    for end in ("cancel", "disarm"):
        session = session_on_simulator()
        done, _ = run(session, until=lambda events: any(e.phase == Phase.EXCITING for e in events))
        stop_index = session.backend.device.next_index
        if end == "cancel":
            assert not session.cancel_cycle(session.sequencer.last_cycle_id + 1, "not this one")
            assert session.cancel_cycle(session.sequencer.last_cycle_id, "the client left")
        else:
            session.disarm("deactivated")
        events = session.step(0.0).events
        assert coil_log(session)[-1] == (stop_index, False)
        reason = "the client left" if end == "cancel" else "deactivated"
        assert [(e.phase, e.reason) for e in events] == [(Phase.IDLE, f"cancelled: {reason}")]
        assert not done[0].success and done[0].message == f"cancelled: {reason}" and done[0].cancelled
        state = session.health()
        assert (state["phase"], state["fault"], state["cycle_running"]) == ("IDLE", "", False)
        session.arm()
        (outcome,), _ = run(session)
        assert outcome.success, outcome.message


def test_a_cycle_started_at_once_after_a_cancel_turns_only_once_the_coils_are_off():
    """A cancel switches the coils off at the device's next sample, which can lie ahead of the
    samples received (in a stream, up to a command lead); a device refuses to turn the probe
    while its coils are on. A cycle asked for at once must wait for the switch-off, not fail."""
    session = session_on_simulator()
    run(session, until=lambda events: any(e.phase == Phase.EXCITING for e in events))
    assert session.cancel_cycle(session.sequencer.last_cycle_id, "the client left")
    done = []
    session.start_cycle(CycleRequest(0.3), done.append)  # before any sample after the cancel
    for _ in range(MAX_STEPS):
        if done:
            break
        session.step(0.0)
    assert done and done[0].success, done[0].message if done else "the cycle did not end"
    stop = coil_log(session)[-2 * FAST.repeats - 2 * FAST.tuning_steps - 1]
    assert stop[1] is False  # the cancelled cycle's switch-off, before the new cycle's drives


def test_a_fault_is_reported_apart_from_the_phase_until_the_next_cycle():
    session = session_on_simulator()
    run(session, until=lambda events: any(e.phase == Phase.EXCITING for e in events))
    session.emergency_stop(True, "operator")
    session.step(0.0)
    state = session.health()
    assert (state["phase"], state["fault"]) == ("IDLE", "emergency stop: operator")
    session.emergency_stop(False, "")
    assert session.health()["fault"] == ""


def test_a_request_out_of_range_is_refused_with_its_reason():
    session = session_on_simulator()
    session.step(0.0)
    with pytest.raises(ValueError, match="repeats = 0"):
        session.start_cycle(CycleRequest(0.0, repeats=0), print)
    with pytest.raises(ValueError, match="theta0_rad"):
        session.start_cycle(CycleRequest(math.nan), print)


# --- the cap ------------------------------------------------------------------------------
SCENARIO = load_scenario()
currents = st.floats(-50.0, 50.0, allow_nan=False)


def one_tone(*amplitudes_a):
    """One probe's coil drive at 110 Hz: a tone of one."""
    return (CoilTone(0, 110.0, amplitudes_a),)


def test_the_probe_turns_while_only_a_switch_off_waits_and_never_while_the_coils_are_on_or_commanded():
    # The host switches the coils off whenever its link comes up; a cycle's first turn can reach
    # the device before that switch-off applies, and must not be refused as "coils are on".
    device = ScheduledDevice(SpyDevice(SCENARIO), CurrentCap(CAP_A))
    device.schedule_coils(0, one_tone(0.0, 0.0))  # the off a link-up sends, not applied yet
    assert device.schedule_orientation(10, 0.5) == 10
    device.read_until(20)
    device.schedule_coils(30, one_tone(1.0, -1.0))
    with pytest.raises(RuntimeError, match="cannot turn"):  # a switch-on waits
        device.schedule_orientation(40, 0.0)
    device.read_until(35)
    device.schedule_coils(50, one_tone(0.0, 0.0))
    with pytest.raises(RuntimeError, match="cannot turn"):  # on, with its switch-off waiting
        device.schedule_orientation(60, 0.0)
    device.read_until(55)
    assert device.schedule_orientation(60, 0.0) == 60
    assert list(device.coil_log) == [(30, True), (50, False)]


@settings(max_examples=60, deadline=None)
@given(st.floats(0.1, 20.0), st.lists(st.tuples(st.integers(0, 400), currents, currents), min_size=1, max_size=6))
def test_no_coil_drive_above_the_cap_reaches_the_simulated_device(cap_a, commands):
    spy = SpyDevice(SCENARIO)
    device = ScheduledDevice(spy, CurrentCap(cap_a))
    limit = min(cap_a, SCENARIO.setup.cap.limit_a)
    for at_index, i1, i2 in commands:
        if max(abs(i1), abs(i2)) > limit:
            with pytest.raises(ValueError, match="exceeds the cap"):
                device.schedule_coils(at_index, one_tone(i1, i2))
        else:
            device.schedule_coils(at_index, one_tone(i1, i2))
    device.read_until(500)
    assert all(np.max(np.abs(drive)) <= limit for drive in spy.drives)


class RecordingDevice:
    """Stands in for a device: takes every command the sequencer issues, applies it at its
    sample (or the next one, if that has passed) and sends blank samples."""

    def __init__(self):
        self.commands = []

    def run(self, sequencer, step):
        """Serve the cycle that ``step`` began until it ends; its outcome."""
        pending, next_index = list(step.commands), sequencer.next_index
        for _ in range(MAX_STEPS):
            if step.outcome is not None:
                return step.outcome
            if pending:
                command = pending.pop(0)
                self.commands.append(command)
                applied = max(command.at_sample_index, next_index)
                step = sequencer.on_result(CommandResult(command.command_id, True, applied))
            else:
                step = sequencer.on_samples(
                    SampleBlock(next_index, next_index * 50_000, 20_000.0, np.zeros((200, 2)), np.zeros((200, 2), bool))
                )
                next_index += 200
            pending += step.commands
        raise AssertionError("the cycle did not end")


@settings(max_examples=80, deadline=None)
@given(
    st.sampled_from([largest_spacing(), helmholtz()]),
    st.floats(0.1, 20.0),
    st.floats(0.0, 30.0),
    st.floats(-100.0, 100.0),
    st.integers(1, 3),
    st.integers(0, 2),
)
def test_no_cycle_ever_commands_a_current_above_the_cap(setup, cap_a, current_a, theta0, repeats, tuning):
    quick = CycleSettings(
        excitation_current_a=current_a,
        excite_s=0.01,
        ringdown_s=0.01,
        gap_s=0.0,
        repeats=repeats,
        tuning_steps=tuning,
        turn_settle_s=0.0,
        max_duty_cycle=1.0,
    )
    sequencer = CycleSequencer(quick, setup, CurrentCap(cap_a), 20_000.0, 110.0, fit=fit_tuning, probes=ONE)
    sequencer.on_samples(SampleBlock(0, 0, 20_000.0, np.zeros((1, 2)), np.zeros((1, 2), bool)))
    device = RecordingDevice()
    # The cap limits what reaches the coils: each coil's current of the orientation-dependent
    # scheme (the base amplitude times sin(θ0 + phase)), and the setup's own amplifier limit on
    # the base amplitude.
    over = current_a > setup.cap.limit_a or max(abs(i) for i in setup.currents_a(theta0, current_a)) > cap_a
    if over:
        with pytest.raises(ValueError, match="cap"):
            sequencer.start(CycleRequest(theta0))
        return
    outcome = device.run(sequencer, sequencer.start(CycleRequest(theta0)))
    assert outcome.success
    coil_commands = [c for c in device.commands if isinstance(c, CoilCommand)]
    assert len(coil_commands) == 2 * (repeats + tuning)
    assert all(abs(i) <= cap_a for c in coil_commands for t in c.tones for i in t.amplitudes_a)


# --- the static-field supply through the session ------------------------------------------------
def supplied_session(supply_cap_a=2.0):
    scenario = load_scenario("calibration")
    backend = SimBackend(SimulatedDevice(scenario), CurrentCap(CAP_A), paced=False, supply_cap_a=supply_cap_a)
    return DeviceSession(
        backend, SessionConfig(0.025, FAST, scenario.setup, CurrentCap(CAP_A), 125.0, fit_tuning), armed=True
    ), backend


def step_until(session, condition, steps=2000):
    for _ in range(steps):
        if condition():
            return
        session.step(0.0)
    raise AssertionError("the condition never held")


def test_the_session_answers_a_supply_current_once_the_device_has_reached_it():
    session, backend = supplied_session()
    answers = []
    session.step(0.0)
    session.set_field_current(1.0, answers.append)
    step_until(session, lambda: answers)
    (result,) = answers
    assert result.accepted and backend.device.device.field_current_a == 1.0
    assert backend.device.next_index > result.applied_sample_index
    with pytest.raises(ValueError, match="cap"):
        session.set_field_current(2.5, answers.append)  # above the driver's supply cap: never sent
    session.close()
    assert backend.device.device.field_current_a == 0.0  # closing ramps the supply down first


def test_the_driver_s_supply_cap_is_lower_than_the_device_s_and_a_cancel_ramps_down_from_midway():
    session, backend = supplied_session(supply_cap_a=1.0)
    with pytest.raises(ValueError, match="cap of 1 A"):
        session.set_field_current(1.5, print)
    answers = []
    session.set_field_current(-1.0, answers.append)
    step_until(session, lambda: backend.device.device.field_current_a <= -0.3)
    session.supply_to_zero()
    step_until(session, lambda: backend.device.device.field_current_a == 0.0 and backend.device.supply_target_a == 0.0)
    assert not answers or answers[0].accepted


def test_the_session_announces_each_ramp_and_where_the_device_reached_it():
    # What mows calibrate BAG reads back: the supply is steady at a current from the sample at
    # which the device reached it (the stamp of that sample), ramping before.
    session, backend = supplied_session()
    events, answers = [], []
    session.step(0.0)
    session.set_field_current(0.5, answers.append)
    for _ in range(2000):
        events += session.step(0.0).supply
        if answers:
            break
    start, steady = events
    assert (start.current_a, start.ramping, steady.current_a, steady.ramping) == (0.5, True, 0.5, False)
    assert steady.sample_index == answers[0].applied_sample_index
    # 0.5 A at 2 A/s in 10 ms steps: the ramp takes 0.25 s (± a step) of device time
    assert (steady.stamp_ns - start.stamp_ns) / 1e9 == pytest.approx(0.25, abs=0.011)
    assert (steady.stamp_ns - start.stamp_ns) * 20_000 == (steady.sample_index - start.sample_index) * 1e9
    session.emergency_stop(True, "test")
    (dropped,) = session.step(0.0).supply
    assert (dropped.current_a, dropped.ramping) == (0.0, True) and "emergency stop: test" in dropped.reason
    assert session.health()["supply_state_a"] == 0.0 and session.health()["supply_ramping"]
    session.close()


def test_a_stop_on_a_supply_never_set_raises_no_ramping_flag():
    session, _ = supplied_session()
    session.step(0.0)
    session.emergency_stop(True, "test")
    assert session.step(0.0).supply == [] and "supply_ramping" not in session.health()


def test_a_cycle_drives_at_the_frequency_it_is_asked_for():
    session = session_on_simulator(
        CycleSettings(excite_s=0.1, ringdown_s=0.2, gap_s=0.0, repeats=1, tuning_steps=0, turn_settle_s=0.0)
    )
    (outcome,), events = run(session, CycleRequest(0.0, frequency_hz=112.9))
    assert outcome.success, outcome.message
    assert {e.frequency_hz for e in events if e.phase == Phase.EXCITING} == {112.9}
    with pytest.raises(ValueError, match="frequency_hz"):
        session.start_cycle(CycleRequest(0.0, frequency_hz=20000.0), lambda _: None)


def test_a_cancelled_cycle_reports_the_ring_downs_it_recorded():
    """Cancelled in its second measurement's excitation, a cycle has recorded one measurement
    ring-down whole (its two tuning ones are no measurements): it says 1, not 0, and the
    half-rung second is not counted."""
    session = session_on_simulator()
    second = lambda events: any(e.phase == Phase.EXCITING and not e.tuning and e.repeat_index == 1 for e in events)  # noqa: E731
    done, events = run(session, until=second)
    assert [(e.tuning, e.repeat_index) for e in events if e.phase == Phase.RINGDOWN][-1] == (False, 0)
    assert session.cancel_cycle(session.sequencer.last_cycle_id, "the client left")
    session.step(0.0)
    assert not done[0].success and done[0].ringdowns_recorded == 1


def _phases_of(scenario) -> list:
    """The phase events of one cycle at θ0 = 30° of ``scenario``'s device, in device time."""
    events = []
    loop = DeviceTimeLoop(
        scheduled_device(scenario, CurrentCap(CAP_A), np.random.default_rng(5)),
        FAST,
        fit=fit_tuning,
        on_event=events.append,
    )
    outcome = loop.run_cycle(CycleRequest(math.radians(30.0), repeats=1, tuning_steps=1))
    assert outcome.success, outcome.message
    return events


def test_a_list_of_one_probe_runs_the_cycle_of_the_older_shape_of_one_probe():
    """One probe on its stage is tuned and driven at the excitation current (to the stop),
    whether its scene gives it as ``probe`` and ``pose`` or as a ``probes:`` list of one."""
    pose = {"magnet_position_m": [0.0, 0.0, 0.0], "theta0_deg": 0.0}
    base = {k: v for k, v in load_scenario().to_dict().items() if k not in ("probe", "pose", "probes")}
    older = base | {"probe": "paper", "pose": pose}
    listed = base | {"probes": [{"probe": "paper", "pose": pose}]}
    first, second = (_phases_of(Scenario.from_dict(d)) for d in (older, listed))
    assert first == second
    exciting = [e for e in first if e.phase == Phase.EXCITING]
    assert [e.tuning for e in exciting] == [True, False]
    expected = largest_spacing().currents_a(math.radians(30.0), FAST.excitation_current_a)
    np.testing.assert_allclose(exciting[0].currents_a, expected)
    assert exciting[0].probe_ids == (0,) and exciting[0].probe_theta0_rad == pytest.approx((math.radians(30.0),))
