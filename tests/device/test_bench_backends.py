"""The paper's bench backends: the NI card through NI's own ``nidaqmx`` package, its C library's
interpreter replaced by the simulated card (:mod:`mows.device.simulated.daqmx_card`, in wall-clock
time), and the NGM202 field supply through PyVISA against pyvisa-sim.

Requirement: a coil drive reaches the amplifiers as V_k = I_k·gain·sin(2πf(i − i_on)/fs) with
the setup's orientation-dependent I_k, on and off at the commanded samples; the fluxgates come
back in tesla, saturated at the input range's end; the supply is set, ramped within its slew
limit and read back, its refusals reported; a missing runtime or card is one clear line. A host
stalled for 1 s, half the paper's output lead, loses nothing; a host stalled beyond the lead
underflows the outputs, and a card error (underflow, overrun, a card pulled out) is a fault with
its reason, the coils and the supply off, and the card re-armed.
"""

import dataclasses
import math
import re
import subprocess
import sys
import time

import nidaqmx
import nidaqmx.stream_writers
import numpy as np
import pytest
from nidaqmx.errors import DaqError

from mows.device.backends import daqmx_tasks
from mows.device.backends.daqmx_backend import open_daqmx
from mows.device.backends.daqmx_tasks import DeviceUnavailable
from mows.device.backends.factory import BackendSettings, BenchSettings, make_backend
from mows.device.cycle.phases import CycleRequest, CycleSettings, Phase
from mows.device.instruments import scpi
from mows.device.instruments.daq import CoilWaveforms, load_daq_device
from mows.device.instruments.scpi import (
    SIMULATED_RESOURCE,
    SIMULATED_SUPPLY_FILE,
    SupplyError,
    load_supply_file,
    open_scpi_supply,
)
from mows.device.instruments.supply_schedule import SupplySchedule
from mows.device.interface import CoilCommand, CoilTone, DeviceFault, FieldCurrentCommand, LinkEvent
from mows.device.simulated.daqmx_card import SimulatedCard
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import CurrentCap, largest_spacing
from mows.physics.supply import RAMP_STEP_S, SupplyLimits
from mows.records.samples import SampleBlock
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

FAST = CycleSettings(excite_s=0.5, ringdown_s=0.3, gap_s=0.1, repeats=1, tuning_steps=1, turn_settle_s=0.1)
MAX_POLLS = 10_000  # bound for a cycle that never ends (a bug), not a timing
# The stall the tests give the host on purpose: half the paper's lead (2 s), the other half left
# to the stalls of a loaded machine itself.
STALL_S = 1.0


def simulated_supply():
    return open_scpi_supply(SIMULATED_RESOURCE, load_supply_file(), f"{SIMULATED_SUPPLY_FILE}@sim")


def supply_state(supply) -> tuple[float, int]:
    """The pyvisa-sim instrument's own current and output state (not through the backend)."""
    properties = supply.resource.visalib.devices[SIMULATED_RESOURCE]._properties
    return properties["current"].get_value(), properties["output"].get_value()


def watchdog(backend, watchdog_s: float) -> None:
    """The backend's watchdog at ``watchdog_s`` from now: a short one only once the test means the
    host to go silent (before, a loaded machine may well pause reading longer than that)."""
    backend.device = dataclasses.replace(backend.device, watchdog_s=watchdog_s)


def poll_for(backend, duration_s: float) -> list:
    """Everything the backend hands out over ``duration_s`` of wall time, polled as a driver does."""
    items: list = []
    end = time.monotonic() + duration_s
    while time.monotonic() < end:
        items += backend.poll(0.05)
    return items


def blocks(items) -> list[SampleBlock]:
    return [i for i in items if isinstance(i, SampleBlock)]


def run_cycle(session, theta0_rad):
    done, events = [], []
    events += session.step(0.0).events
    session.start_cycle(CycleRequest(theta0_rad, turned_by_hand=True), done.append)
    for _ in range(MAX_POLLS):
        if done:
            return done[0], events
        events += session.step(0.0).events
    raise AssertionError("the cycle did not end")


# --- the waveforms and the inputs, without a card ------------------------------------------------
@pytest.mark.parametrize("theta0_deg", [0.0, 45.0, 100.0, 225.0])
def test_the_outputs_carry_the_orientation_dependent_amplitudes(theta0_deg):
    theta0 = math.radians(theta0_deg)
    amplitudes = largest_spacing().currents_a(theta0, 2.0)
    waves = CoilWaveforms(2, 20_000.0, 0.8)
    assert waves.schedule(100, amplitudes, 112.5) == 100
    volts = waves.synthesise(100 + 20_000)
    # Independent of the scheme's code: coil 1 ∝ sin(θ0 + 135°), coil 2 ∝ sin(θ0 + 45°) (Methods).
    expected_peak = 0.8 * 2.0 * np.abs(np.sin(theta0 + np.radians([135.0, 45.0])))
    np.testing.assert_allclose(np.max(np.abs(volts), axis=1), expected_peak, atol=1e-6)
    signs = np.sign(volts[:, 101] / math.sin(2 * math.pi * 112.5 / 20_000.0))
    np.testing.assert_array_equal(
        signs[expected_peak > 1e-9], np.sign(np.sin(theta0 + np.radians([135.0, 45.0])))[expected_peak > 1e-9]
    )
    assert not volts[:, :101].any()


def test_a_drive_for_a_written_sample_applies_at_the_first_unwritten_one():
    waves = CoilWaveforms(2, 20_000.0, 1.0)
    waves.synthesise(500)
    assert waves.schedule(200, (1.0, -1.0), 100.0) == 500
    assert waves.schedule(900, (0.0, 0.0), 0.0) == 900
    volts = waves.synthesise(1000)
    assert volts[:, 1:400].any() and not volts[:, 400:].any()
    assert waves.off_now() == 1000 and not waves.coils_on


def test_inputs_at_the_range_end_are_saturated_and_scaled_to_tesla():
    device = load_daq_device()
    volts = np.array([[0.5, 10.0, -10.0, 9.9], [-0.25, 0.0, 1e-3, -9.99999]])
    field, saturated = device.field_t(volts)
    np.testing.assert_allclose(field[:, 0], [0.5e-6, 10e-6, -10e-6, 9.9e-6])
    np.testing.assert_array_equal(saturated[:, 0], [False, True, True, False])
    np.testing.assert_array_equal(saturated[:, 1], [False, False, False, True])  # within half a code of −10 V


def test_a_device_file_whose_cap_the_outputs_cannot_reach_is_refused(tmp_path):
    text = load_daq_device.__defaults__[0].read_text().replace("amplifier_v_per_a: 1.0", "amplifier_v_per_a: 2.0")
    path = tmp_path / "card.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=r"card.yaml: .*current_cap_a × amplifier_v_per_a = 20 V exceeds Dev1/ao0"):
        load_daq_device(path)
    path.write_text(text.replace("amplifier_v_per_a: 2.0", "amplifier_v_per_a: 1.0\nspeed: 3"))
    with pytest.raises(ValueError, match=r"unknown keys \['speed'\]"):
        load_daq_device(path)


BAD_BENCH_FILES = {  # (the shipped file, its line, the line instead), and the refusal after the file's name
    "device: both fluxgates on one input": (
        "device",
        ("physical_channel: Dev1/ai1", "physical_channel: dev1/AI0"),
        r"inputs\[1\].physical_channel = 'dev1/AI0' is inputs\[0\]'s too: each fluxgate needs a channel of its own",
    ),
    "device: both coils on one output": (
        "device",
        ("physical_channel: Dev1/ao1", "physical_channel: Dev1/ao0"),
        r"outputs\[1\].physical_channel = 'Dev1/ao0' is outputs\[0\]'s too: .*",
    ),
    "device: an infinite rate": (
        "device",
        ("sample_rate_hz: 20000.0", "sample_rate_hz: .inf"),
        "sample_rate_hz = inf must be a finite number",
    ),
    "device: a sensitivity as text": (
        "device",
        ("sensitivity_v_per_t: 1.0e+6}  # far", 'sensitivity_v_per_t: "1e6"}  # far'),
        r"inputs\[1\].sensitivity_v_per_t = '1e6' is not a number",
    ),
    "device: a negative range": (
        "device",
        ("range_v: 10.0}  # coil 2", "range_v: -1e1}  # coil 2"),
        r"outputs\[1\].range_v = -10.0 .*",
    ),
    "supply: a NaN voltage limit": (
        "supply",
        ("voltage_limit_v: 10.0", "voltage_limit_v: .nan"),
        "voltage_limit_v = nan must be a finite number",
    ),
    "supply: a negative voltage limit": (
        "supply",
        ("voltage_limit_v: 10.0", "voltage_limit_v: -1e1"),
        "voltage_limit_v = -10.0 must be a finite number > 0",
    ),
    "supply: an integer format for the current": (
        "supply",
        ('set_current: "CURR {:.4f}"', 'set_current: "CURR {:d}"'),
        r"commands.set_current = 'CURR \{:d\}' must hold one \{\} for the value, formatting a float .*",
    ),
    "supply: an unclosed format": (
        "supply",
        ('set_current: "CURR {:.4f}"', 'set_current: "CURR {:.4f"'),
        r"commands.set_current = 'CURR \{:.4f' must hold one \{\} .*",
    ),
    "supply: no value in the command": (
        "supply",
        ('set_current: "CURR {:.4f}"', 'set_current: "CURR 1"'),
        r"commands.set_current = 'CURR 1' must hold one \{\} .*",
    ),
    "supply: a named value": (
        "supply",
        ('output: "OUTP {:d}"', 'output: "OUTP {on:d}"'),
        r"commands.output = 'OUTP \{on:d\}' must hold one \{\} for the value, formatting a int.*",
    ),
    "supply: a channel that is no integer": (
        "supply",
        ("channel: 1", "channel: 1.5"),
        "channel = 1.5 is not an integer",
    ),
    "supply: a cap as text": ("supply", ("cap_a: 2.0", "cap_a: 2 A"), "cap_a = '2 A' is not a number"),
}


@pytest.mark.parametrize("case", BAD_BENCH_FILES)
def test_a_bad_bench_file_is_refused_in_one_line_naming_the_file_key_and_value(tmp_path, case):
    kind, (line, instead), message = BAD_BENCH_FILES[case]
    load = load_daq_device if kind == "device" else load_supply_file
    text = load.__defaults__[0].read_text()
    assert line in text
    path = tmp_path / "bench.yaml"
    path.write_text(text.replace(line, instead, 1))
    with pytest.raises(ValueError) as refused:
        load(path)
    assert re.fullmatch(f"{kind} file {re.escape(str(path))}: {message}", str(refused.value)), refused.value


def test_bench_files_read_numbers_as_yaml_1_2(tmp_path):
    path = tmp_path / "supply.yaml"
    path.write_text(load_supply_file.__defaults__[0].read_text().replace("resolution_a: 1.0e-4", "resolution_a: 1e-4"))
    assert load_supply_file(path).limits.resolution_a == 1e-4


# --- the nidaqmx backend on the simulated card --------------------------------------------------
def test_without_nis_runtime_the_backend_says_so_in_one_line():
    try:
        nidaqmx.Task().close()
    except nidaqmx.errors.DaqNotFoundError:
        pass
    else:
        pytest.skip("NI-DAQmx is installed on this machine")
    with pytest.raises(DeviceUnavailable) as error:
        open_daqmx(load_daq_device(), CurrentCap(10.0))
    assert "NI-DAQmx" in str(error.value) and "\n" not in str(error.value)


FRESH_START = """
import importlib, sys
from mows.device.backends import daqmx_backend
from mows.device.instruments.daq import load_daq_device
from mows.device.simulated.daqmx_card import SimulatedCard
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

card = SimulatedCard(SimulatedDevice(load_scenario()))
with card.installed():
    print("stream modules loaded:", "nidaqmx.stream_readers" in sys.modules or "nidaqmx.stream_writers" in sys.modules)
    try:  # NI's package as plain `import nidaqmx` gives it
        daqmx_backend.DaqmxBackend(importlib.import_module("nidaqmx"), load_daq_device(), CurrentCap(10.0))
    except AttributeError as error:
        print("plain import:", error, "; tasks left open:", len(card.tasks))
    backend = daqmx_backend.open_daqmx(load_daq_device(), CurrentCap(10.0))
    print("open_daqmx: blocks read", any(hasattr(i, "samples_t") for i in backend.poll(0.1)))
    backend.close()
"""


def test_the_backend_imports_nis_stream_readers_and_writers_itself():
    # A fresh interpreter: in this one another test may have imported them already. Its bound is
    # for a hang, below pytest's own: a fresh interpreter at load 36 took more than 120 s.
    run = subprocess.run([sys.executable, "-c", FRESH_START], capture_output=True, text=True, timeout=540)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert lines[0] == "stream modules loaded: False"  # `import nidaqmx` loads neither
    assert "stream_readers" in lines[1] and lines[1].endswith("tasks left open: 0")
    assert lines[2] == "open_daqmx: blocks read True"  # one, or more on a loaded host behind the card


def test_a_card_that_is_not_there_is_one_line_naming_it(installed):
    card = installed(SimulatedCard(SimulatedDevice(load_scenario()), inputs=("Dev2/ai0", "Dev2/ai1")))
    with pytest.raises(DeviceUnavailable) as error:
        open_daqmx(load_daq_device(), CurrentCap(10.0))
    assert str(error.value).startswith("backend nidaqmx: card 'Dev1': Device identifier is invalid")
    assert "(-200220)" in str(error.value) and "\n" not in str(error.value)
    assert len(card.made) == 2 and not card.tasks  # nothing is left open on the card
    with pytest.raises(DeviceUnavailable):  # so a second try is refused for the card, not for the names
        open_daqmx(load_daq_device(), CurrentCap(10.0))
    assert len(card.made) == 4 and not card.tasks


def test_the_tasks_are_made_as_the_api_requires(on_bench):
    card, backend = on_bench()
    ai, ao = card.made
    assert [c for c, _ in ai.channels] == ["Dev1/ai0", "Dev1/ai1"] and [c for c, _ in ao.channels] == [
        "Dev1/ao0",
        "Dev1/ao1",
    ]
    assert ao.trigger == "/Dev1/ai/StartTrigger" and ai.rate_hz == ao.rate_hz == 20_000.0
    assert (ai.name, ao.name) == ("mows_fluxgates", "mows_coils") and ai.running and ao.running
    backend.close()
    assert not card.tasks and not ai.running and not ao.running


def test_the_simulated_card_refuses_what_the_real_one_refuses(installed):
    installed(SimulatedCard(SimulatedDevice(load_scenario())))
    constants = nidaqmx.constants
    with nidaqmx.Task("ao") as ao:
        ao.ao_channels.add_ao_voltage_chan("Dev1/ao0")
        ao.timing.cfg_samp_clk_timing(20_000.0, sample_mode=constants.AcquisitionType.CONTINUOUS)
        ao.out_stream.regen_mode = constants.RegenerationMode.DONT_ALLOW_REGENERATION
        ao.ao_channels.all.ao_idle_output_behavior = constants.AOIdleOutputBehavior.ZERO_VOLTS
        ao.triggers.start_trigger.cfg_dig_edge_start_trig("/Dev1/ai/StartTrigger")
        with pytest.raises(DaqError, match="output buffer is empty") as empty:
            ao.start()
        assert empty.value.error_code == -200462
        writer = nidaqmx.stream_writers.AnalogMultiChannelWriter(ao.out_stream, auto_start=False)
        with pytest.raises(DaqError, match="out of range"):
            writer.write_many_sample(np.full((1, 10), 11.0))
        with pytest.raises(nidaqmx.errors.DaqWriteError, match="larger than the space"):
            writer.write_many_sample(np.zeros((1, 1001)))
        with pytest.raises(DaqError) as duplicate:
            nidaqmx.Task("ao")
        assert duplicate.value.error_type == nidaqmx.error_codes.DAQmxErrors.DUPLICATE_TASK


def armed_session(card, backend, frequency_hz=112.0) -> DeviceSession:
    """The driver's session on the bench, armed, its cycles ``FAST``."""
    config = SessionConfig(0.025, FAST, card.device.scenario.setup, CurrentCap(10.0), frequency_hz, fit_tuning)
    return DeviceSession(backend, config, armed=True)


def test_a_cycle_switches_the_coils_at_the_commanded_samples(on_bench):
    card, backend = on_bench()
    session = armed_session(card, backend)
    theta0 = 2.2
    card.turn_probe(theta0)
    outcome, events = run_cycle(session, theta0)
    backend.close()  # before the truth is computed: a bench left streaming unread would underflow
    assert outcome.success, outcome.message
    on = [e for e in events if e.phase == Phase.EXCITING]
    off = [e for e in events if e.phase == Phase.RINGDOWN]
    # What the coils got, read back from the output volts, is what the sequencer commanded.
    assert [d[0] for d in card.drives] == [e.sample_index for e in on]
    assert card.offs == [e.sample_index for e in off]
    expected = largest_spacing().currents_a(theta0, FAST.excitation_current_a)
    for (_, amplitudes, frequency_hz), event in zip(card.drives, on):
        np.testing.assert_allclose(amplitudes, expected, rtol=1e-9)
        assert frequency_hz == pytest.approx(event.frequency_hz, rel=1e-9)
    # The tuned frequency is the probe's resonance at the bench's field (10 mHz, as the sim backend).
    assert outcome.frequency_hz == pytest.approx(card.device.expected_frequencies_hz()[0], abs=0.01)
    assert card.underflows == card.overruns == backend.card_faults == 0


def test_commands_above_the_cap_are_refused_and_never_written(on_bench):
    card, backend = on_bench()
    with pytest.raises(ValueError, match="exceeds the cap"):
        backend.send(CoilCommand(1, 5000, (CoilTone(0, 112.0, (10.5, 0.0)),)))
    poll_for(backend, 0.5)
    assert not card.drives
    backend.close()


def drive(backend, items, duration_s=2.0, command_id=1):
    """A drive of ``duration_s`` from the first sample the backend takes; its on and off samples."""
    backend.send(CoilCommand(command_id, 0, (CoilTone(0, 112.0, (0.5, -0.3)),)))
    items += backend.poll(0.05)
    on = next(i.applied_sample_index for i in items if getattr(i, "command_id", None) == command_id)
    off = on + round(duration_s * 20_000.0)
    backend.send(CoilCommand(command_id + 1, off))
    return on, off


def supply_at(backend, current_a: float, items: list) -> None:
    backend.send(FieldCurrentCommand(100, 0, current_a))
    while backend.supply_pending:
        items += backend.poll(0.05)


def test_a_host_stalled_for_half_the_lead_mid_drive_loses_nothing(on_bench):
    """The paper's device file as it is (its lead and its watchdog), the supply on, the coils
    driving: a host stall of STALL_S underflows nothing and faults nothing; the drive ends as
    commanded, the stream has no gap and the supply stays on at its current."""
    supply = simulated_supply()
    card, backend = on_bench("calibration", supply, watchdog_s=None)
    assert backend.device.stall_survived_s >= 2 * STALL_S
    items: list = []
    supply_at(backend, 1.0, items)
    on, off = drive(backend, items, duration_s=3.0)
    while not card.drives:
        items += backend.poll(0.05)
    time.sleep(STALL_S)  # the host stalls with the coils on (a tuning fit, a busy machine)
    for _ in range(MAX_POLLS):
        items += backend.poll(0.05)
        if backend.next_index > off:
            break
    assert card.underflows == 0 and backend.card_faults == 0
    assert not [i for i in items if isinstance(i, (LinkEvent, DeviceFault))]
    assert [d[0] for d in card.drives] == [on] and card.offs == [off]  # the drive as commanded
    read = blocks(items)
    assert all(b.first_sample_index == a.first_sample_index + len(a) for a, b in zip(read, read[1:]))  # no gap
    assert supply_state(supply) == (1.0, 1)
    backend.close()
    assert supply_state(supply) == (0.0, 0)


def test_a_host_stalled_beyond_the_lead_has_the_coils_and_the_supply_off_a_fault_told_and_the_card_re_armed(
    on_bench,
):
    supply = simulated_supply()
    card, backend = on_bench("calibration", supply)
    items: list = []
    supply_at(backend, 1.0, items)
    lead_s = backend.device.output_lead_s
    on, off = drive(backend, items, duration_s=lead_s + 3.0)
    while not card.drives:
        items += backend.poll(0.05)
    time.sleep(lead_s + 0.5)  # beyond the lead: the card generates all it has, then underflows
    before = len(items)
    items += backend.poll(0.05)
    assert len(items[before:]) == 3, (items[before:], backend.stats())
    down, up, fault = items[before:]
    assert not down.up and "(-200290)" in down.reason and down.reason.startswith("the card stopped: outputs:")
    assert up.up and up.reason == f"the card re-armed after: {down.reason}" and fault.reason == down.reason
    assert backend.stats()["card_faults"] == 1 and backend.stats()["last_card_fault"] == down.reason
    # Told once the supply is safe: ramped down within its slew limit and switched off.
    assert supply_state(supply) == (0.0, 0)
    # The coils went off where the written samples ended, before the commanded switch-off.
    assert card.underflows == 1 and len(card.offs) == 1 and on < card.offs[0] < off
    items += poll_for(backend, 1.0)
    assert len(card.drives) == 1  # the queued switch-off and nothing else: no stale drive comes back
    assert backend.stats()["link"] == "nidaqmx" and not backend.stats()["device_coils_on"]
    assert supply_state(supply) == (0.0, 0)
    read = blocks(items)
    gap = [b for a, b in zip(read, read[1:]) if b.first_sample_index != a.first_sample_index + len(a)]
    assert len(gap) == 1 and gap[0].first_sample_index > read[0].first_sample_index  # on, after the lost time
    backend.close()


def test_an_input_overrun_is_told_beside_the_outputs_underflow(on_bench, monkeypatch):
    monkeypatch.setattr(daqmx_tasks, "INPUT_BUFFER_S", 0.3)
    card, backend = on_bench()
    poll_for(backend, 0.2)
    time.sleep(backend.device.output_lead_s + 0.5)
    (down, up, _) = backend.poll(0.05)
    assert "outputs:" in down.reason and "(-200290)" in down.reason
    assert "inputs:" in down.reason and "(-200279)" in down.reason and card.overruns == 1
    assert up.up
    backend.close()


def test_a_card_pulled_out_is_closed_at_once_and_re_armed_when_it_is_back(on_bench):
    card, backend = on_bench()
    poll_for(backend, 0.2)
    card.unplug()
    items = poll_for(backend, 1.0)
    (down,) = [i for i in items if isinstance(i, LinkEvent)]
    assert not down.up and "(-201003)" in down.reason and not card.tasks  # its tasks closed, not left running
    assert not blocks(items[items.index(down) :]) and backend.stats()["link"] == "down"
    assert "re-arming:" in backend.stats()["last_card_fault"]
    card.plug_in()
    items = poll_for(backend, 2.5)
    (up,) = [i for i in items if isinstance(i, LinkEvent)]
    assert up.up and blocks(items) and len(card.tasks) == 2
    backend.close()
    assert not card.tasks


def test_after_a_card_fault_the_supply_is_at_zero_and_off(on_bench):
    supply = simulated_supply()
    card, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 1.0))
    while backend.supply_pending:
        backend.poll(0.05)
    assert supply_state(supply) == (1.0, 1)
    card.unplug()
    (down,) = backend.poll(0.05)
    # Told once the supply is safe: ramped down within its slew limit and switched off.
    assert not down.up and supply_state(supply) == (0.0, 0)
    card.plug_in()
    items = poll_for(backend, 1.5)
    assert [i.up for i in items if isinstance(i, LinkEvent)] == [True] and supply_state(supply) == (0.0, 0)
    backend.send(FieldCurrentCommand(2, 0, 0.2))  # a new ramp switches it on again, from zero
    while backend.supply_pending:
        backend.poll(0.05)
    assert supply_state(supply) == (0.2, 1)
    backend.close()
    assert supply_state(supply) == (0.0, 0)


# --- the SCPI supply against pyvisa-sim -----------------------------------------------------------
def instrument_setting(supply, name):
    return supply.resource.visalib.devices[SIMULATED_RESOURCE]._properties[name].get_value()


class Sent:
    """What a supply's resource was sent, in order; ``refuse`` makes the writes of one command fail."""

    def __init__(self, supply, refuse=()):
        self.commands: list[str] = []
        self._write = supply.resource.write
        self.refuse = refuse
        supply.resource.write = self.write

    def write(self, command):
        if not command.endswith("?"):  # a query is written too
            self.commands.append(command)
        if command in self.refuse:
            raise OSError("VI_ERROR_TMO (-1073807339): Timeout expired before operation completed.")
        return self._write(command)


def test_the_supply_is_set_read_back_after_it_settles_and_switched():
    supply = simulated_supply()
    config = supply.config
    assert supply.identity.startswith("Rohde&Schwarz,NGM202")
    assert supply_state(supply) == (0.0, 1)  # prepared: zero current, output on
    supply.set_current_a(0.12345)
    assert instrument_setting(supply, "current") == 0.1234  # rounded to the 0.1 mA resolution, not clipped
    # At once the pair has not settled: a read-back compared now is a false alarm.
    assert abs(supply.read_current_a() - 0.1234) > config.readback_tolerance_a(0.1234)
    time.sleep(config.settle_s)
    assert supply.read_current_a() == pytest.approx(0.1234, abs=config.readback_tolerance_a(0.1234))
    readings = [supply.read_current_a() for _ in range(20)]
    assert np.std(readings) > 0.0  # a read-back is a measurement, not the setting echoed
    with pytest.raises(ValueError, match="exceeds the cap of 2 A"):
        supply.set_current_a(2.5)
    assert supply_state(supply)[0] == pytest.approx(0.1234)
    supply.close()
    assert supply_state(supply) == (0.0, 0)
    time.sleep(config.settle_s)
    assert supply.resource.visalib.instruments[SIMULATED_RESOURCE].delivered_a() == pytest.approx(0.0, abs=1e-5)


def test_the_supply_is_cleared_identified_and_protected_before_its_output_goes_on():
    supply = simulated_supply()
    supply.close()
    supply.resource.open()
    supply.resource.write("FOO")  # an old error in the queue: cleared at open, not blamed on the first command
    sent = Sent(supply)
    supply.prepare()
    assert sent.commands[0] == "*CLS"
    on = sent.commands.index("OUTP 1")
    protections = ["CURR:ALIM 2.0000", "VOLT:ALIM 10.000", "ALIM 1", "VOLT:PROT:LEV 12.000", "VOLT:PROT 1"]
    assert all(sent.commands.index(c) < on for c in [*protections, "CURR 0.0000", "VOLT 10.000"])
    assert sent.commands[on + 1 :] == ["OUTP:GEN 1"]  # the master output, which this model has
    assert instrument_setting(supply, "safety_limits") == 1 and instrument_setting(supply, "general") == 1
    assert instrument_setting(supply, "current_safety_limit") == 2.0
    assert instrument_setting(supply, "over_voltage_level") == 12.0
    assert instrument_setting(supply, "over_voltage_protection") == 1
    supply.close()


def test_a_model_without_a_master_output_is_not_sent_one(tmp_path):
    path = tmp_path / "supply.yaml"
    path.write_text(load_supply_file.__defaults__[0].read_text().replace('"OUTP:GEN {:d}"', '""'))
    supply = open_scpi_supply(SIMULATED_RESOURCE, load_supply_file(path), f"{SIMULATED_SUPPLY_FILE}@sim")
    sent = Sent(supply)
    supply.prepare()
    assert not [c for c in sent.commands if c.startswith("OUTP:GEN")]
    supply.close()


def test_another_model_at_the_address_is_refused_with_its_name_and_sent_nothing(tmp_path):
    path = tmp_path / "other.yaml"
    path.write_text(SIMULATED_SUPPLY_FILE.read_text().replace("Rohde&Schwarz,NGM202,", "Rohde&Schwarz,NGL202,"))
    with pytest.raises(SupplyError) as refused:
        open_scpi_supply(SIMULATED_RESOURCE, load_supply_file(), f"{path}@sim")
    assert "model 'NGL202', not the supply file's 'NGM202'" in str(refused.value)
    import pyvisa

    device = pyvisa.ResourceManager(scpi._library(f"{path}@sim")).visalib.devices[SIMULATED_RESOURCE]
    assert device._properties["output"].get_value() == 0 and device._properties["safety_limits"].get_value() == 0


def test_every_entry_of_the_error_queue_is_read_and_reported():
    supply = simulated_supply()
    supply.set_current_a(0.5)
    for bad in ("CURR 7.0000", "FOO", "VOLT 99.000"):  # three errors queued behind the supply's back
        supply.resource.write(bad)
    with pytest.raises(SupplyError) as refused:
        supply.set_current_a(0.25)
    out_of_range, unknown = '-222,"Data out of range"', '-100,"Command error"'  # the NGM202's codes
    assert str(refused.value) == f"ngm202: 'CURR 0.2500' refused: {out_of_range}; {unknown}; {out_of_range}"
    supply.set_current_a(0.25)  # the queue was drained: the next command is judged on its own
    assert supply_state(supply) == (0.25, 1)
    supply.close()


def test_close_zeroes_and_switches_off_each_whatever_the_other_did_then_returns_to_local():
    supply = simulated_supply()
    supply.set_current_a(0.5)
    sent = Sent(supply, refuse={"CURR 0.0000"})
    with pytest.raises(SupplyError, match=r"'CURR 0.0000': VI_ERROR_TMO"):
        supply.close()
    # Every channel's output and the master output off, each whatever the others did.
    assert sent.commands == ["CURR 0.0000", "OUTP 0", "INST:NSEL 2", "OUTP 0", "INST:NSEL 1", "OUTP:GEN 0", "SYST:LOC"]
    assert supply_state(supply) == (0.5, 0)  # the current could not be zeroed: the output is off


def test_an_output_that_stays_on_is_read_back_and_said(tmp_path):
    """The switch-off is read back (OUTP?): a relay that sticks is a problem named, not a belief."""
    text = SIMULATED_SUPPLY_FILE.read_text().replace('q: "OUTP?"\n          r: "{:d}"', 'q: "OUTP?"\n          r: "1"')
    assert text != SIMULATED_SUPPLY_FILE.read_text()
    path = tmp_path / "sticky.yaml"
    path.write_text(text)
    supply = open_scpi_supply(SIMULATED_RESOURCE, load_supply_file(), f"{path}@sim")
    supply.set_current_a(0.5)
    assert supply.safe() == ["ngm202: OUTP? reads back on after the output was switched off"]
    assert simulated_supply().safe() == []


def session_at_half_an_ampere(on_bench):
    """A session on the bench with the simulated supply ramped to 0.5 A and read back so."""
    supply = simulated_supply()
    card, backend = on_bench("calibration", supply)
    config = SessionConfig(0.025, FAST, card.device.scenario.setup, CurrentCap(10.0), 112.5, fit_tuning)
    session = DeviceSession(backend, config, armed=True)
    session.set_field_current(0.5, lambda result: None)
    for _ in range(MAX_POLLS):
        session.step(0.0)
        if backend.stats()["supply_output"] == "on":  # read back once settled at 0.5 A
            break
    assert supply_state(supply) == (0.5, 1)
    return supply, backend, session


def test_after_an_emergency_stop_the_supply_is_ramped_to_zero_and_switched_off(on_bench):
    supply, backend, session = session_at_half_an_ampere(on_bench)
    assert session.emergency_stop(True, "test")
    seen = []
    for _ in range(MAX_POLLS):
        session.step(0.0)
        seen.append(supply_state(supply))
        if seen[-1][1] == 0:
            break
    assert seen[-1] == (0.0, 0) and not backend.fault  # at zero, then off, read back so
    assert all(current <= 0.5 for current, _ in seen) and len({c for c, _ in seen}) > 3  # ramped, not stepped
    session.emergency_stop(False, "")
    session.set_field_current(0.2, lambda result: None)  # a new ramp switches it on again, from zero
    for _ in range(MAX_POLLS):
        session.step(0.0)
        if not backend.supply_schedule.ramping and supply_state(supply) == (0.2, 1):
            break
    assert supply_state(supply) == (0.2, 1)
    session.close()
    assert supply_state(supply) == (0.0, 0)


def test_a_supply_error_mid_ramp_leaves_it_at_zero_and_off(on_bench):
    supply = simulated_supply()
    card, backend = on_bench("calibration", supply)
    steps = [f"CURR {current_a:.4f}" for _, current_a in supply.config.limits.ramp(0.0, 0.6)]
    refused = steps[len(steps) // 2]  # mid-ramp
    sent = Sent(supply, refuse={refused})
    backend.send(FieldCurrentCommand(1, 0, 0.6))
    items = []
    for _ in range(MAX_POLLS):
        items += backend.poll(0.05)
        if any(isinstance(i, LinkEvent) for i in items):
            break
    down = next(i for i in items if isinstance(i, LinkEvent))
    assert not down.up and "the supply failed" in down.reason and f"'{refused}'" in down.reason
    assert supply_state(supply) == (0.0, 0) and "OUTP 0" in sent.commands
    backend.close()
    assert supply_state(supply) == (0.0, 0)


def test_the_ngm202_is_unipolar_and_a_negative_current_is_never_sent():
    supply = simulated_supply()
    assert supply.config.limits.polarity == "unipolar" and supply.config.limits.range_a() == (0.0, 2.0)
    supply.set_current_a(0.5)
    writes = supply.writes
    with pytest.raises(
        ValueError, match=r"^supply current -0\.1 A is outside the supply's range 0 … \+2 A \(unipolar\)"
    ):
        supply.set_current_a(-0.1)
    assert supply.writes == writes and supply_state(supply) == (0.5, 1)
    # The stand-in refuses it as the NGM202 does, had it been sent.
    supply.resource.write("CURR -0.1000")
    assert supply.resource.query("SYST:ERR?").startswith("-222") and supply_state(supply) == (0.5, 1)
    supply.close()


def test_a_command_the_supply_refuses_is_an_error_naming_it(tmp_path):
    config = load_supply_file()
    text = SIMULATED_SUPPLY_FILE.read_text().replace('q: "CURR {:.4f}"', 'q: "SOUR:CURR {:.4f}"')
    path = tmp_path / "other.yaml"
    path.write_text(text)
    with pytest.raises(SupplyError, match=r"ngm202: 'CURR 0.0000' refused: -100"):
        open_scpi_supply(SIMULATED_RESOURCE, config, f"{path}@sim")


def test_another_supply_is_a_file(tmp_path):
    supply_text = (
        load_supply_file.__defaults__[0]
        .read_text()
        .replace('set_current: "CURR {:.4f}"', 'set_current: "SOUR:CURR {:.4f}"')
    )
    (tmp_path / "supply.yaml").write_text(supply_text)
    sim_text = SIMULATED_SUPPLY_FILE.read_text().replace('q: "CURR {:.4f}"', 'q: "SOUR:CURR {:.4f}"')
    (tmp_path / "sim.yaml").write_text(sim_text)
    supply = open_scpi_supply(
        SIMULATED_RESOURCE, load_supply_file(tmp_path / "supply.yaml"), f"{tmp_path / 'sim.yaml'}@sim"
    )
    supply.set_current_a(1.5)
    time.sleep(supply.config.settle_s)
    assert supply.read_current_a() == pytest.approx(1.5, abs=supply.config.readback_tolerance_a(1.5))
    supply.close()


def test_a_ramp_steps_within_the_slew_limit_on_the_sample_clock():
    limits = SupplyLimits(2.0, 2.0, 1e-4)
    schedule = SupplySchedule(limits, 20_000.0)
    end = schedule.ramp(100, 50, 1.0)
    assert end == 100 + round(0.49 * 20_000.0)  # 0.5 s at 2 A/s: 50 steps of 10 ms, the first at once
    steps = schedule.due(end + 1)
    assert len(steps) == 50 and steps[-1] == 1.0
    assert np.max(np.abs(np.diff([0.0, *steps]))) <= 2.0 * 0.01 + 1e-12
    schedule.ramp(0, end + 1, 0.5)
    schedule.due(end + 200)
    back = schedule.to_zero(end + 200)
    assert schedule.due(back + 1)[-1] == 0.0 and not schedule.ramping


def test_a_host_behind_the_card_reads_the_supply_back_settled(on_bench):
    """A host that stalled gets a ramp's samples in a burst and writes its steps one after the
    other: the supply settles from the last write in its own time, however far the card's clock
    has run on by then."""
    supply = simulated_supply()
    bench, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 0.5))
    time.sleep(0.5)  # the stall: the ramp (0.24 s) and settle_s after it are buffered on the card
    while backend.supply_schedule.ramping:
        backend.poll(0.0)
    assert math.isnan(backend.supply_readback.current_a)
    while backend.supply_pending:
        backend.poll(0.0)
    tolerance = supply.config.readback_tolerance_a(0.5)
    assert backend.supply_readback.current_a == pytest.approx(0.5, abs=tolerance)
    assert bench.device.field_current_a == 0.5
    backend.close()


def test_the_backend_ramps_the_supply_and_zeroes_it_on_close(on_bench, monkeypatch):
    supply = simulated_supply()
    sim = supply.resource.visalib.instruments[SIMULATED_RESOURCE]
    written: list[float] = []  # each current as the instrument received it
    match = sim._device._match

    def recorded(query):
        if query.startswith(b"CURR "):
            written.append(float(query.split()[1]))
        return match(query)

    monkeypatch.setattr(sim._device, "_match", recorded)
    bench, backend = on_bench("calibration", supply)
    backend.send(FieldCurrentCommand(1, 0, 0.5))
    (result,) = backend.poll(0.0)[:1]
    assert result.accepted and result.applied_sample_index == round(0.24 * 20_000.0)
    while backend.supply_schedule.ramping:
        backend.poll(0.0)
    assert math.isnan(backend.supply_readback.current_a)  # not at once: the pair is still settling
    while backend.supply_pending:  # the steps written, and read back once the last has settled
        backend.poll(0.0)
    assert backend.supply_readback.step_index == result.applied_sample_index
    tolerance = supply.config.readback_tolerance_a(0.5)
    assert backend.supply_readback.current_a == pytest.approx(0.5, abs=tolerance)
    assert bench.device.field_current_a == 0.5
    # Every step of the staircase reaches the instrument, in order, none skipped: at most one
    # step's worth of the slew limit apart (the line paces them one per step, however late the
    # host hands them over).
    step_a = supply.config.limits.slew_a_per_s * RAMP_STEP_S
    assert written[-1] == 0.5 and len(written) >= round(0.5 / step_a)
    assert np.max(np.diff([0.0, *written])) <= step_a + 1e-9 and np.all(np.diff(written) > 0.0)
    with pytest.raises(ValueError, match="exceeds the cap"):
        backend.send(FieldCurrentCommand(2, 0, 2.5))
    backend.close()
    assert supply_state(supply) == (0.0, 0)


def test_without_a_supply_a_field_current_is_refused_with_the_reason(on_bench):
    _, backend = on_bench()
    backend.send(FieldCurrentCommand(7, 0, 0.5))
    (result,) = backend.poll(0.0)[:1]
    assert not result.accepted and "no field supply" in result.reason
    backend.close()


def test_a_host_that_stops_reading_has_the_coils_and_the_supply_switched_off(on_bench):
    supply = simulated_supply()
    card, backend = on_bench("calibration", supply)
    ao = card.made[1]
    backend.send(FieldCurrentCommand(1, 0, 0.3))
    while backend.supply_pending:
        backend.poll(0.0)
    assert supply_state(supply)[0] == pytest.approx(0.3)
    watchdog(backend, 0.2)
    deadline = time.monotonic() + 30.0  # a bound for a watchdog that never trips, not a timing
    while supply_state(supply) != (0.0, 0) and time.monotonic() < deadline:
        time.sleep(0.05)  # the host is silent: no poll
    assert supply_state(supply)[0] == 0.0 and not ao.running
    assert supply_state(supply) == (0.0, 0) and not card.tasks  # the output off, the tasks closed
    watchdog(backend, 30.0)  # the host reads again, as a loaded one does
    down, up, fault = backend.poll(0.0)  # the card re-armed on the next read
    assert not down.up and down.reason.startswith("watchdog: no read for") and fault.reason == down.reason
    assert up.up and ao not in card.tasks.values() and len(card.tasks) == 2
    assert not [i for i in backend.poll(0.05) if isinstance(i, LinkEvent)]  # told once
    backend.close()
    assert supply_state(supply) == (0.0, 0)


def test_the_driver_s_supply_cap_lowers_the_supply_file_s_and_never_raises_it(installed):
    assert BenchSettings(supply_current_cap_a=5.0).supply_config().limits.cap_a == 2.0  # the NGM202's own
    installed(SimulatedCard(SimulatedDevice(load_scenario("calibration"))))
    settings = BackendSettings(
        backend="nidaqmx",
        supply="scpi",
        supply_resource=SIMULATED_RESOURCE,
        visa_library=f"{SIMULATED_SUPPLY_FILE}@sim",
        supply_current_cap_a=1.5,
    )
    backend = make_backend(settings, CurrentCap(10.0))
    try:
        assert backend.supply.config.limits.cap_a == 1.5
        with pytest.raises(ValueError, match="exceeds the cap"):
            backend.send(FieldCurrentCommand(1, 0, 1.8))
    finally:
        backend.close()
    assert supply_state(backend.supply) == (0.0, 0)


def test_the_emergency_stop_s_switch_off_holds_through_a_deactivation_and_close(on_bench):
    """A supply the emergency stop switched off is not switched on again to be ramped to zero."""
    supply, backend, session = session_at_half_an_ampere(on_bench)
    session.emergency_stop(True, "test")
    for _ in range(MAX_POLLS):
        session.step(0.0)
        if backend.stats()["supply_output"] == "off":
            break
    session.disarm("deactivated")
    end = time.monotonic() + 2.0 * supply.config.settle_s
    while time.monotonic() < end:
        session.step(0.05)
        assert supply_state(supply) == (0.0, 0)
    stats, tolerance = backend.stats(), supply.config.readback_tolerance_a(0.0)
    assert stats["supply_output"] == "off" and abs(stats["supply_readback_a"]) <= tolerance
    session.close()
    assert backend.closed_state() == f"supply off at {backend.supply_readback.current_a:.4f} A (read back)"


def test_the_simulated_bench_is_the_backend_on_the_simulated_card_until_it_is_closed():
    """``daq_simulated``: no card installed by the test; NI's package drives the simulated one
    while the backend is open, its own library again once closed."""
    from nidaqmx import _library_interpreter

    real = _library_interpreter.LibraryInterpreter
    settings = BackendSettings(backend="nidaqmx", supply="scpi", daq_simulated=True)
    backend = make_backend(settings, CurrentCap(10.0))
    try:
        assert _library_interpreter.LibraryInterpreter is not real
        assert backend.supply.identity.startswith("Rohde&Schwarz,NGM202")
        assert blocks(poll_for(backend, 0.2))
    finally:
        backend.close()
    assert _library_interpreter.LibraryInterpreter is real
    assert supply_state(backend.supply) == (0.0, 0) and backend.closed_state().startswith("supply off at ")


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        (BackendSettings(daq_simulated=True), "daq_simulated=True goes with backend nidaqmx, not 'sim'"),
        (
            BackendSettings(backend="nidaqmx", supply="scpi", supply_resource="ASRL1::INSTR", daq_simulated=True),
            "supply_resource='ASRL1::INSTR': the simulated bench's supply is at 'TCPIP0::192.168.0.20::inst0::INSTR'",
        ),
    ],
)
def test_the_simulated_bench_refuses_what_it_cannot_be(settings, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        make_backend(settings, CurrentCap(10.0))
