"""The rule behind the driver's lifecycle, without ROS: a device session energises a coil only
while it is armed (the driver ``active``). Disarmed it refuses cycles and supply currents with
the reason, disarming switches the coils off at the device's next sample, and the one place
that sends commands refuses a coil drive even when the refusal upstream is missing."""

import pytest

from mows.device.backends.sim_backend import SimBackend
from mows.device.cycle.phases import CycleRequest, CycleSettings, Phase
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

CAP_A = 10.0
QUICK = CycleSettings(excite_s=0.3, ringdown_s=0.3, gap_s=0.1, repeats=1, tuning_steps=0, turn_settle_s=0.1)
MAX_STEPS = 100_000  # bound for a loop that never ends (a bug), not a timing
INACTIVE = "the driver is inactive"


def session_on(scene="calibration") -> DeviceSession:
    scenario = load_scenario(scene)
    backend = SimBackend(SimulatedDevice(scenario), CurrentCap(CAP_A), paced=False, supply_cap_a=2.0)
    return DeviceSession(backend, SessionConfig(0.025, QUICK, scenario.setup, CurrentCap(CAP_A), 125.0, fit_tuning))


def step_until(session, condition) -> list:
    events = []
    for _ in range(MAX_STEPS):
        if condition(events):
            return events
        events += session.step(0.0).events
    raise AssertionError("the condition never held")


def coils_ever_on(session) -> bool:
    return any(on for _, on in session.backend.device.coil_log)


def test_a_session_starts_disarmed_and_refuses_cycles_and_supply_currents_with_the_reason():
    session = session_on()
    session.disarm(INACTIVE)
    session.step(0.0)
    with pytest.raises(ValueError, match=INACTIVE):
        session.start_cycle(CycleRequest(0.0), print)
    with pytest.raises(ValueError, match=INACTIVE):
        session.set_field_current(1.0, print)
    answers = []
    session.set_field_current(0.0, answers.append)  # to zero is always allowed: it de-energises
    step_until(session, lambda _: answers)
    step_until(session, lambda _: session.backend.device.next_index > 20_000)  # a second of samples
    assert not coils_ever_on(session) and session.backend.device.device.field_current_a == 0.0
    assert session.health()["armed"] is False


def test_disarming_mid_excitation_switches_off_at_the_next_sample_ends_the_cycle_without_a_fault():
    session = session_on()
    session.arm()
    session.step(0.0)
    supply = []
    session.set_field_current(1.0, supply.append)
    step_until(session, lambda _: supply)
    done = []
    session.start_cycle(CycleRequest(0.5), done.append)
    step_until(session, lambda events: any(e.phase == Phase.EXCITING for e in events))
    assert session.backend.device.coils_on and not done
    next_index = session.backend.device.next_index
    session.disarm(INACTIVE)
    events = step_until(session, lambda _: session.backend.device.device.field_current_a == 0.0)
    assert session.backend.device.coil_log[-1] == (next_index, False)  # off at the next device sample
    assert not session.backend.device.coils_on
    ((outcome,), ended) = done, [e for e in events if e.phase in (Phase.IDLE, Phase.FAULT)]
    assert not outcome.success and INACTIVE in outcome.message
    # a deactivation is no fault of the cycle's: it ends IDLE, with the reason
    assert ended and ended[0].phase == Phase.IDLE and INACTIVE in ended[0].reason and not ended[0].coils_on
    with pytest.raises(ValueError, match=INACTIVE):
        session.start_cycle(CycleRequest(0.0), print)
    session.arm()  # active again: cycles run
    again = []
    session.start_cycle(CycleRequest(0.0), again.append)
    step_until(session, lambda _: again)
    assert again[0].success, again[0].message


def test_no_coil_drive_leaves_a_disarmed_session_even_when_its_cycle_is_already_running():
    """The last guard: a cycle started while armed whose session is then marked disarmed
    without :meth:`disarm` (what a bug upstream would do) never switches a coil on."""
    session = session_on()
    session.arm()
    session.step(0.0)
    done = []
    session.start_cycle(CycleRequest(0.5), done.append)  # sends the stage turn, no coil yet
    session.armed, session.disarmed_reason = False, INACTIVE
    step_until(session, lambda _: done)
    (outcome,) = done
    assert not outcome.success and "may not be energised" in outcome.message and INACTIVE in outcome.message
    assert not coils_ever_on(session)
