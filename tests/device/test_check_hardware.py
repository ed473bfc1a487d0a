"""``mows check-hardware``: the step-by-step check of the paper's bench, on the simulated bench
(NI's ``nidaqmx`` on the simulated card and the NGM202 on pyvisa-sim). Requirement: every check
passes on a bench wired as its device file says, a wiring fault shows as a PROBLEM line naming it,
and a card that faults or a supply that refuses a step ends the check with PROBLEM and the reason,
never a hang."""

import re
import subprocess
import sys

import numpy as np
import pytest

from mows.cli.check_hardware import PROBLEM_EXIT
from mows.cli.main import main
from mows.device.backends.daqmx_backend import open_daqmx
from mows.device.backends.factory import simulated_card
from mows.device.instruments.daq import load_daq_device
from mows.device.instruments.hardware_check import HardwareCheck, lock_in_t
from mows.device.instruments.scpi import SIMULATED_RESOURCE, SIMULATED_SUPPLY_FILE, load_supply_file, open_scpi_supply
from mows.physics.coils import CurrentCap


def test_the_simulated_bench_passes_every_check(capsys):
    assert main(["check-hardware", "--simulate"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("card Dev1 (paper_pcie6363), supply Rohde&Schwarz,NGM202")
    assert [line.split(":")[0] for line in lines[1:]] == [
        "ok      fluxgates at rest",
        "ok      coil 1 at 0.02 A, 300 Hz, 0.2 s",
        "ok      coil 2 at 0.02 A, 300 Hz, 0.2 s",
        "ok      field supply",
        "ok      cleanup",
    ]
    assert lines[-1] == f"ok      cleanup: supply off at {float(lines[-1].split()[5]):.4f} A (read back)"
    # Each read-back within the NGM202 file's stated accuracy of the setting, once settled.
    readback = re.search(r"set 0\.1000 A, read back (\S+) A .*; set 0 A, read back (\S+) A", lines[-2])
    back_a, zero_a = (float(value) for value in readback.groups())
    assert abs(back_a - 0.1) <= 1.1e-3 and abs(zero_a) <= 1.1e-3
    assert "(± 1.1 mA)" in lines[-2]


def test_a_fluxgate_on_an_unwired_input_is_a_problem():
    device = load_daq_device()
    supply = open_scpi_supply(SIMULATED_RESOURCE, load_supply_file(), f"{SIMULATED_SUPPLY_FILE}@sim")
    card = simulated_card(device, supply)
    card.inputs = ("Dev1/ai0", "Dev1/ai5")  # the far fluxgate's cable on another terminal
    with card.installed():
        backend = open_daqmx(device, CurrentCap(10.0), supply)
        try:
            lines = HardwareCheck(backend).run()
        finally:
            backend.close()
    assert not lines[0].ok and lines[0].saw.endswith(
        "fluxgate 2 +0.000 µT ± 0 nT rms, 0 of 20000 saturated (flat: is it wired to its input?)"
    )
    assert [line.ok for line in lines[1:]] == [True, True, True]  # fluxgate 1 still sees both coils


def test_the_lock_in_reads_a_sinusoid_and_ignores_others():
    t = np.arange(4000) / 20_000.0
    x = np.stack([3e-9 * np.sin(2 * np.pi * 112.5 * t + 0.4) + 1e-6, 5e-9 * np.sin(2 * np.pi * 50.0 * t)], axis=1)
    seen = lock_in_t(x, 112.5, 20_000.0)
    assert seen[0] == pytest.approx(3e-9, rel=1e-3)
    # A rectangular window over T leaks a tone Δf away by at most 1/(π·Δf·T) of its amplitude.
    assert seen[1] < 5e-9 / (np.pi * 62.5 * 0.195)
    with pytest.raises(ValueError, match="no whole period"):
        lock_in_t(x[:100], 112.5, 20_000.0)


def test_without_the_card_the_supply_is_switched_off_again(monkeypatch, capsys):
    closed = []
    real_open = open_scpi_supply

    def opened(*args):
        supply = real_open(SIMULATED_RESOURCE, load_supply_file(), f"{SIMULATED_SUPPLY_FILE}@sim")
        closed.append(supply)
        return supply

    def no_card(*args):
        raise OSError("no card")

    monkeypatch.setattr("mows.device.backends.factory.open_scpi_supply", opened)
    monkeypatch.setattr("mows.device.backends.factory.open_daqmx", no_card)
    assert main(["check-hardware", "--supply-resource", "TCPIP0::1.2.3.4::inst0::INSTR"]) == 2
    assert "mows check-hardware: error: no card" in capsys.readouterr().err
    properties = closed[0].resource.visalib.devices[SIMULATED_RESOURCE]._properties
    assert (properties["current"].get_value(), properties["output"].get_value()) == (0.0, 0)


# A check that has not ended by then hangs: the bound, not a timing (at load 12 on two cores the
# interpreter's start and imports alone take 15 s of wall time).
HANG_BOUND_S = 300.0
PULLED_OUT = """
import sys, threading, time
from mows.cli.main import main
from mows.device.backends import factory

made = factory.simulated_card


def pulled_out_mid_check(device, supply):
    card = made(device, supply)

    def pull_out():  # during the first coil's pulse, once the card has read its start
        while not card.drives:
            time.sleep(0.01)
        card.unplug()

    threading.Thread(target=pull_out, daemon=True).start()
    return card


factory.simulated_card = pulled_out_mid_check
sys.exit(main(["check-hardware", "--simulate"]))
"""


def check_in_a_process(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, *args], capture_output=True, text=True, timeout=HANG_BOUND_S, check=False)


def test_a_card_that_faults_mid_check_ends_it_with_the_reason():
    run = check_in_a_process("-c", PULLED_OUT)
    assert run.returncode == PROBLEM_EXIT, run.stderr
    lines = run.stdout.splitlines()
    assert lines[1].startswith("ok      fluxgates at rest")
    assert lines[2].startswith("PROBLEM coil 1 at 0.02 A, 300 Hz, 0.2 s: stopped: the link went down: the card stopped")
    assert "(-201003)" in lines[2] and lines[2].endswith("the checks after it were not run")
    assert lines[3].startswith("ok      cleanup: supply off at") and len(lines) == 4


REFUSING_SUPPLY = """
import sys
from mows.cli.main import main
from mows.device.backends import factory

factory.SIMULATED_SUPPLY_FILE = sys.argv[1]
sys.exit(main(["check-hardware", "--simulate", "--supply-step-a", "1.5"]))
"""


def test_a_supply_that_refuses_a_step_ends_the_check_with_the_reason(tmp_path):
    # The file allows 2 A, this instrument sources 1 A: the ramp's steps above 1 A are refused mid-check.
    instrument = tmp_path / "ngm202_1a.yaml"
    instrument.write_text(
        SIMULATED_SUPPLY_FILE.read_text().replace(
            "max: 2.0\n          type: float\n      voltage:", "max: 1.0\n          type: float\n      voltage:"
        )
    )
    run = check_in_a_process("-c", REFUSING_SUPPLY, str(instrument))
    assert run.returncode == PROBLEM_EXIT, run.stderr
    lines = run.stdout.splitlines()
    assert [line.split(":")[0] for line in lines[1:4]] == [
        "ok      fluxgates at rest",
        "ok      coil 1 at 0.02 A, 300 Hz, 0.2 s",
        "ok      coil 2 at 0.02 A, 300 Hz, 0.2 s",
    ]
    assert lines[4].startswith("PROBLEM field supply: stopped: the link went down: the supply failed:")
    assert "THE SUPPLY" not in lines[4]  # ramped to zero and switched off all the same


def test_a_supply_file_whose_cap_the_instrument_does_not_allow_is_refused_at_open(tmp_path):
    # The file allows 3 A, the instrument's safety limit 2 A: refused before its output goes on.
    supply_file = tmp_path / "supply.yaml"
    supply_file.write_text(load_supply_file.__defaults__[0].read_text().replace("cap_a: 2.0", "cap_a: 3.0"))
    args = ["-m", "mows.cli.main", "check-hardware", "--simulate"]
    run = check_in_a_process(*args, "--supply-file", str(supply_file), "--supply-step-a", "2.5")
    assert run.returncode == 2 and not run.stdout
    assert run.stderr == "mows check-hardware: error: ngm202: 'CURR:ALIM 3.0000' refused: -222,\"Data out of range\"\n"
