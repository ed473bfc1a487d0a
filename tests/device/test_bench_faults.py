"""The paper's bench fails safe on every path (NI's ``nidaqmx`` on the simulated card, the NGM202
through pyvisa-sim with latency, lost messages, -222 and over-voltage trips).

Requirement: the watchdog is fed by successful reads only; a supply read-back is judged only
against the step it follows; a cycle whose turn the operator did not make is refused; the
check's results survive a failed cleanup; a sample rate the card's timebase does not divide is
refused; on close every output of the supply is off and read back so; the supply's I/O never
holds up the card's stream, and an exchange that hangs, times out, is refused or trips the
output is a fault that leaves the supply at zero and off.
"""

import dataclasses
import threading
import time

import pytest

from device.test_bench_backends import (
    MAX_POLLS,
    armed_session,
    blocks,
    poll_for,
    run_cycle,
    simulated_supply,
    supply_state,
    watchdog,
)
from mows.cli.main import main
from mows.device.backends.daqmx_backend import open_daqmx
from mows.device.backends.daqmx_tasks import DeviceUnavailable
from mows.device.cycle.phases import CycleRequest
from mows.device.instruments import scpi
from mows.device.instruments.daq import load_daq_device
from mows.device.instruments.hardware_check import HardwareCheck
from mows.device.instruments.scpi import (
    SIMULATED_RESOURCE,
    SIMULATED_SUPPLY_FILE,
    SupplyError,
    load_supply_file,
    open_scpi_supply,
)
from mows.device.interface import FieldCurrentCommand, LinkEvent
from mows.device.simulated.daqmx_card import SimulatedCard
from mows.physics.coils import CurrentCap
from mows.records.samples import SampleBlock
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

BOUND_S = 30.0  # a bound for what never happens (a bug), not a timing


def instrument(supply):
    return supply.resource.visalib.instruments[SIMULATED_RESOURCE]


def settle(backend) -> list:
    """Poll until the supply's steps are written and read back; what the backend handed out."""
    items: list = []
    deadline = time.monotonic() + BOUND_S
    while backend.supply_pending and time.monotonic() < deadline:
        items += backend.poll(0.05)
    return items


def poll_until_down(backend) -> LinkEvent:
    deadline = time.monotonic() + BOUND_S
    while time.monotonic() < deadline:
        for item in backend.poll(0.05):
            if isinstance(item, LinkEvent) and not item.up:
                return item
    raise AssertionError("the bench never went down")


def test_a_driver_whose_every_read_fails_has_the_supply_switched_off(on_bench, monkeypatch):
    supply = simulated_supply()
    card, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 1.0))
    settle(backend)
    assert supply_state(supply) == (1.0, 1)

    def broken(*args, **kwargs):
        raise RuntimeError("a read that fails in the host, not on the card")

    monkeypatch.setattr(backend._reader, "read_many_sample", broken)
    watchdog(backend, 0.3)
    failed, deadline = 0, time.monotonic() + BOUND_S
    while (supply_state(supply) != (0.0, 0) or not failed) and time.monotonic() < deadline:
        try:  # the driver's stream thread never dies on a step: it polls again
            backend.poll(0.05)
        except RuntimeError:
            failed += 1
        time.sleep(0.02)
    assert supply_state(supply) == (0.0, 0) and failed >= 1
    assert backend.stats()["last_card_fault"].startswith("watchdog: no read for")
    backend.close()


class StallsBeforeTheZero:
    """The bench's backend on a host that stalls just before the block where the supply's step
    back to zero ends (a loaded machine): the card's samples wait in its buffer meanwhile."""

    def __init__(self, backend, stall_s: float):
        self._backend, self._stall_s = backend, stall_s
        self._zero_id, self._zero_at = -1, None

    def __getattr__(self, name):
        return getattr(self._backend, name)

    def send(self, command):
        if isinstance(command, FieldCurrentCommand) and command.current_a == 0.0:
            self._zero_id = command.command_id
        self._backend.send(command)

    def poll(self, timeout_s):
        block = self._backend.device.block_samples
        if self._zero_at is not None and self._backend.next_index + 2 * block > self._zero_at:
            self._zero_at = None
            time.sleep(self._stall_s)
        items = self._backend.poll(timeout_s)
        for item in items:
            if getattr(item, "command_id", None) == self._zero_id and self._zero_id > 0:
                self._zero_at, self._zero_id = item.applied_sample_index, -1
        return items


def test_check_hardware_judges_the_read_back_of_the_step_it_checks(on_bench):
    supply = simulated_supply()
    _, backend = on_bench("calibration", supply)
    try:
        lines = HardwareCheck(StallsBeforeTheZero(backend, 0.4)).run()
    finally:
        backend.close()
    assert lines[-1].ok, lines[-1]
    assert "; set 0 A, read back 0.000" in lines[-1].saw or "; set 0 A, read back -0.000" in lines[-1].saw


def test_the_nidaqmx_bench_refuses_a_turn_the_operator_did_not_make(on_bench):
    card, backend = on_bench()
    session = armed_session(card, backend)
    done: list = []
    session.step(0.0)
    session.start_cycle(CycleRequest(1.5707963), done.append)  # a mapper that thinks a motor turns it
    for _ in range(MAX_POLLS):
        if done:
            break
        session.step(0.0)
    assert not done[0].success and "turned by hand" in done[0].message and not card.drives
    assert card.device.truth.theta_rad[0] == pytest.approx(0.0, abs=0.01)  # the probe stayed where it was
    card.turn_probe(1.5707963)
    outcome, _ = run_cycle(session, 1.5707963)  # the operator's turn, confirmed
    assert outcome.success, outcome.message
    session.close()


def test_check_hardware_prints_its_results_before_a_cleanup_that_fails(monkeypatch, capsys):
    close = scpi.ScpiSupply.close

    def fails(self):
        close(self)
        raise SupplyError("ngm202: 'SYST:LOC': VI_ERROR_TMO (-1073807339): Timeout expired")

    monkeypatch.setattr(scpi.ScpiSupply, "close", fails)
    assert main(["check-hardware", "--simulate"]) == 3
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[0] for line in lines[1:]] == [
        "ok      fluxgates at rest",
        "ok      coil 1 at 0.02 A, 300 Hz, 0.2 s",
        "ok      coil 2 at 0.02 A, 300 Hz, 0.2 s",
        "ok      field supply",
        "PROBLEM cleanup",
    ]
    assert "'SYST:LOC': VI_ERROR_TMO" in lines[-1] and lines[-1].endswith("check the supply's front panel")


def test_a_rate_the_cards_timebase_does_not_divide_is_refused(installed):
    card = installed(SimulatedCard(SimulatedDevice(load_scenario())))
    device = dataclasses.replace(load_daq_device(), sample_rate_hz=30_000.0)
    with pytest.raises(DeviceUnavailable) as refused:
        open_daqmx(device, CurrentCap(10.0))
    message = str(refused.value)
    assert "samples at 30003.000300 S/s, not sample_rate_hz = 30000" in message and "100 MHz" in message
    assert not card.tasks  # nothing left open
    backend = open_daqmx(load_daq_device(), CurrentCap(10.0))  # 20 kS/s: 100 MHz / 5000
    assert [t.rate_hz for t in card.tasks.values()] == [20_000.0, 20_000.0]
    backend.close()


def test_on_close_every_output_and_the_master_output_are_off_and_read_back(on_bench):
    supply = simulated_supply()
    _, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 0.3))
    settle(backend)
    supply.resource.write("INST:NSEL 2")  # the other channel switched on at the front panel
    supply.resource.write("OUTP 1")
    supply.resource.write("INST:NSEL 1")
    backend.close()
    sim = instrument(supply)
    properties = supply.resource.visalib.devices[SIMULATED_RESOURCE]._properties
    assert supply_state(supply) == (0.0, 0) and properties["general"].get_value() == 0
    assert sim.other_outputs == {2: 0}


def test_a_supply_ten_milliseconds_per_exchange_does_not_hold_up_the_card(on_bench, monkeypatch):
    """Every exchange with the supply happens off the thread that polls the card (the driver's
    stream thread): at 10 ms each, a ramp's steps written there made the host fall a second
    behind the card's samples."""
    supply = simulated_supply()
    sim = instrument(supply)
    monkeypatch.setattr(sim, "latency_s", 0.01)
    exchanged_on = []
    match = sim._device._match

    def recorded(query):
        exchanged_on.append(threading.current_thread())
        return match(query)

    monkeypatch.setattr(sim._device, "_match", recorded)
    card, backend = on_bench("calibration", supply)
    items = []
    for command_id, current_a in ((1, 2.0), (2, 0.0)):  # two full ramps: 200 steps, 400 exchanges
        backend.send(FieldCurrentCommand(command_id, 0, current_a))
        items += settle(backend)
    assert supply_state(supply) == (0.0, 1) and len(exchanged_on) >= 400
    assert threading.current_thread() not in exchanged_on
    assert card.underflows == 0 and backend.card_faults == 0
    assert not [i for i in items if isinstance(i, LinkEvent)]
    read = blocks(items)
    assert all(b.first_sample_index == a.first_sample_index + len(a) for a, b in zip(read, read[1:]))
    backend.close()


def quick_supply():
    """The simulated supply with a VISA timeout of 0.2 s (a lost answer costs that, not 2 s)."""
    config = dataclasses.replace(load_supply_file(), timeout_s=0.2)
    return open_scpi_supply(SIMULATED_RESOURCE, config, f"{SIMULATED_SUPPLY_FILE}@sim")


def test_a_supply_that_stops_answering_mid_ramp_is_a_fault_and_ends_at_zero_and_off(on_bench):
    supply = quick_supply()
    card, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 1.0))
    while supply_state(supply)[0] < 0.3:
        backend.poll(0.05)
    instrument(supply).lose(2)  # a step and its error query lost, as over a dropped link
    down = poll_until_down(backend)
    assert "the supply failed" in down.reason and "VI_ERROR_TMO" in down.reason
    assert "THE SUPPLY" not in down.reason  # ramped to zero and switched off once it answered again
    assert supply_state(supply) == (0.0, 0) and card.underflows == 0
    backend.close()


def test_an_exchange_past_its_deadline_is_a_fault_without_holding_up_the_card(on_bench, monkeypatch):
    supply = quick_supply()
    card, backend = on_bench("calibration", supply)
    monkeypatch.setattr(instrument(supply), "latency_s", 1.0)  # beyond twice the 0.2 s timeout
    backend.send(FieldCurrentCommand(1, 0, 0.5))
    down = poll_until_down(backend)
    assert down.reason.startswith("the supply did not answer within 0.4 s")
    assert "THE SUPPLY MAY STILL BE ON" in down.reason  # said, not hidden: it was not read back off
    assert card.underflows == 0
    monkeypatch.setattr(instrument(supply), "latency_s", 0.002)
    settle(backend)  # it answers again: the ramp to zero goes on
    backend.close()
    assert supply_state(supply) == (0.0, 0)


def test_a_supply_slow_but_answering_is_ramped_to_zero_to_the_end_on_a_fault(on_bench, monkeypatch):
    """Each exchange within its deadline, the ramp to zero long (a loaded host, a slow link):
    waited for to its end, not cut short with a false alarm."""
    supply = quick_supply()  # each exchange's deadline 0.4 s
    card, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 0.5))
    settle(backend)
    monkeypatch.setattr(instrument(supply), "latency_s", 0.05)  # 0.1 s a step: 50 steps take 5 s
    card.unplug()
    down = poll_until_down(backend)
    assert "(-201003)" in down.reason and "THE SUPPLY" not in down.reason, down.reason
    assert supply_state(supply) == (0.0, 0)
    card.plug_in()
    backend.close()


def test_an_over_voltage_trip_is_a_fault_and_the_next_ramp_clears_it(on_bench):
    supply = simulated_supply()
    _, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 0.5))
    settle(backend)
    instrument(supply).trip_over_voltage()
    down = poll_until_down(backend)
    assert "its output went off by itself (its over-voltage protection tripped)" in down.reason
    assert supply_state(supply) == (0.0, 0)
    settle(backend)
    backend.send(FieldCurrentCommand(2, 0, 0.2))
    settle(backend)
    assert supply_state(supply) == (0.2, 1) and not instrument(supply).tripped
    backend.close()
    assert supply_state(supply) == (0.0, 0)


def test_a_host_behind_its_card_that_stalls_beyond_the_lead_is_told_at_once(on_bench):
    """Behind the card (its outputs written ahead of the sample it generates, beyond the newest
    block read), then stalled beyond the lead: the outputs underflow, and the next poll says so,
    although it has nothing new to write."""
    card, backend = on_bench()
    poll_for(backend, 0.2)
    time.sleep(0.5)  # behind the card by half a second, within the lead
    backend.poll(0.05)  # one block read; the outputs written the lead ahead of the card's sample
    time.sleep(backend.device.output_lead_s + 0.5)  # a stall beyond the lead
    told = [i for i in backend.poll(0.05) if not isinstance(i, SampleBlock)]
    assert [type(i).__name__ for i in told] == ["LinkEvent", "LinkEvent", "DeviceFault"], told
    down, up, _ = told
    assert not down.up and "(-200290)" in down.reason and up.up and card.underflows == 1
    backend.close()


def test_a_supply_failure_met_as_the_card_faults_is_told_with_the_fault(on_bench):
    """The supply's line failed (a lost answer) and the card faulted before the driver took the
    failure: the card's fault tells both, rather than dropping the supply's."""
    supply = quick_supply()
    card, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 1.0))
    while supply_state(supply)[0] < 0.3:
        backend.poll(0.05)
    instrument(supply).lose(2)
    deadline = time.monotonic() + BOUND_S
    while not backend.supply_line._failure and time.monotonic() < deadline:  # not polled: not taken
        time.sleep(0.01)
    card.unplug()
    down = poll_until_down(backend)
    assert "(-201003)" in down.reason and "the supply failed" in down.reason and "VI_ERROR_TMO" in down.reason
    assert supply_state(supply) == (0.0, 0)
    card.plug_in()
    backend.close()
