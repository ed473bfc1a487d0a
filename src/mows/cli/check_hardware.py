"""``mows check-hardware``: check the paper's bench step by step before measuring on it.

Opens the NI card of ``--device`` (default: the paper's PCIe-6363 wiring) and the SCPI field
supply of ``--supply-file`` at ``--supply-resource``
(:func:`mows.device.backends.factory.open_bench`), then
(:class:`mows.device.instruments.hardware_check.HardwareCheck`) reads both fluxgates at rest,
pulses each coil on its own at a safe current and says what each fluxgate saw of it, steps the
supply and reads it back, and reports every check. ``--simulate`` runs the same check on the
simulated bench, as the driver's ``daq_simulated`` does: NI's ``nidaqmx`` on the simulated card
(:func:`mows.device.backends.factory.simulated_card`) over the paper's largest-spacing scene with
the Pasco pair on its supply, the NGM202 on pyvisa-sim.
Every check's line is printed before the bench is closed; the cleanup is a line of its own, a
PROBLEM when the supply could not be switched off and read back so. Exit status 0 when every
check and the cleanup passed, 3 when one found a problem (each line says which).
"""

from __future__ import annotations

import argparse

from mows.cli.inputs import finite_float, positive_float
from mows.device.backends.factory import BenchSettings, open_bench
from mows.device.instruments.daq import PAPER_DEVICE_FILE, load_daq_device
from mows.device.instruments.hardware_check import CheckLine, HardwareCheck
from mows.device.instruments.scpi import PAPER_SUPPLY_FILE, SIMULATED_RESOURCE
from mows.physics.coils import CurrentCap
from mows.physics.probe import PAPER_PROBE

PROBLEM_EXIT = 3


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--device", default=str(PAPER_DEVICE_FILE), help="the card's device YAML")
    parser.add_argument("--supply-file", default=str(PAPER_SUPPLY_FILE), help="the supply's YAML (commands, limits)")
    parser.add_argument("--supply-resource", default="", help="the supply's VISA address ('' : no supply check)")
    parser.add_argument("--visa-library", default="@py", help="PyVISA backend (@py: pyvisa-py, no vendor VISA)")
    parser.add_argument(
        "--coil-current-a", type=positive_float, default=0.02, help="the safe current of each coil's pulse, A"
    )
    parser.add_argument(
        "--frequency-hz", type=positive_float, default=300.0, help="the pulses' frequency, Hz (away from the resonance)"
    )
    parser.add_argument("--supply-step-a", type=finite_float, default=0.1, help="the supply's test current, A")
    parser.add_argument("--simulate", action="store_true", help="check the simulated bench instead")


def run(args) -> int:
    resource = SIMULATED_RESOURCE if args.simulate else args.supply_resource
    bench = BenchSettings(args.device, args.supply_file, resource, args.visa_library, simulated=args.simulate)
    device = load_daq_device(bench.daq_device_file)
    config = bench.supply_config()
    cap = CurrentCap(device.current_cap_a)
    cap.check(args.coil_current_a)
    config.limits.check(args.supply_step_a)
    _check_frequency(args.frequency_hz, device.sample_rate_hz)
    if abs(args.supply_step_a) <= 2.0 * config.readback_tolerance_a(args.supply_step_a):
        raise ValueError(
            f"--supply-step-a {args.supply_step_a:g} A is within the read-back's tolerance of 0 "
            f"(± {config.readback_tolerance_a(args.supply_step_a):.2g} A): the check would test nothing; "
            "give a larger step"
        )
    backend = open_bench(bench, cap)
    try:
        supply = backend.supply
        print(f"card {device.device_name} ({device.name}), supply {supply.identity if supply else 'none'}")
        check = HardwareCheck(
            backend,
            args.coil_current_a,
            args.frequency_hz,
            supply_step_a=args.supply_step_a,
            supply_config=config,
            names=tuple(f"fluxgate {k + 1} ({i.physical_channel})" for k, i in enumerate(device.inputs)),
        )
        lines = check.run(supply=supply is not None)
        for line in lines:
            print(line, flush=True)  # before the cleanup, which may fail: what was seen is kept
    except BaseException:
        backend.close()
        raise
    lines.append(cleanup(backend))
    print(lines[-1])
    return 0 if all(line.ok for line in lines) else PROBLEM_EXIT


def cleanup(backend) -> CheckLine:
    """Close the bench (coils off, the supply ramped to zero, every output off and read back) and
    say how it was left, or what failed."""
    try:
        backend.close()
    except OSError as error:
        return CheckLine("cleanup", False, f"{error}; check the supply's front panel")
    return CheckLine("cleanup", True, backend.closed_state() or "the card's tasks closed")


#: A coil's pulse is read back by a lock-in: this many samples per period at least.
MIN_SAMPLES_PER_PERIOD = 10
#: Pulses this close (relative) to the probe's f00 make the magnet ring: the fluxgates would read
#: its swing, not the coil.
RESONANCE_BAND = 0.05


def _check_frequency(frequency_hz: float, sample_rate_hz: float) -> None:
    highest = sample_rate_hz / MIN_SAMPLES_PER_PERIOD
    if frequency_hz > highest:
        raise ValueError(
            f"--frequency-hz {frequency_hz:g} Hz is above {highest:g} Hz: the card's {sample_rate_hz:g} S/s "
            f"give fewer than {MIN_SAMPLES_PER_PERIOD} samples a period to read the pulse back"
        )
    if abs(frequency_hz / PAPER_PROBE.f00_hz - 1.0) < RESONANCE_BAND:
        raise ValueError(
            f"--frequency-hz {frequency_hz:g} Hz is within {RESONANCE_BAND:.0%} of the probe's resonance "
            f"({PAPER_PROBE.f00_hz:.2f} Hz): the magnet would ring and the fluxgates read its swing, not the coil; "
            "choose a frequency away from it (default 300 Hz)"
        )
