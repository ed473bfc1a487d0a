"""``mows sim``: simulate measurement cycles of a scenario and write the samples to .npz.

For every θ0 and repeat one cycle of the driver's own sequencer on the simulated device
(:func:`mows.device.stream.simulated_cycle.simulate_cycle`): turn, settle for the scenario's gap,
excite, record the ring-down. With ``--fit`` each ring-down is fitted as the estimator node does
(:func:`mows.estimate.recorded_cycle.fit_cycle`: the lever-aware pickup) and compared with the
truth from the full potential
(:meth:`mows.device.stream.simulated_cycle.CycleRecord.ringdown_frequency_hz`). ``--out`` writes
a new file (:func:`mows.device.stream.simulated_cycle.cycles_npz`; an existing one only with
``--force``, never the scenario), whole or not at all.
"""

from __future__ import annotations

import argparse
import math

import numpy as np
import yaml

from mows.cli.inputs import finite_float, input_file, positive_int
from mows.device.stream.simulated_cycle import cycles_npz, simulate_cycle
from mows.estimate.recorded_cycle import fit_cycle
from mows.physics import ranges
from mows.records.files import check_output, writing
from mows.sim.scenario import DEFAULT_SCENARIO, load_scenario
from mows.sim.simulator import SimulatedDevice


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scenario", nargs="?", default=DEFAULT_SCENARIO, help=f"scenario name or YAML file (default {DEFAULT_SCENARIO})"
    )
    parser.add_argument(
        "--theta0-deg",
        type=finite_float,
        nargs="+",
        default=None,
        help="probe orientations, degrees (default: the scenario's)",
    )
    parser.add_argument("--repeats", type=positive_int, default=1, help="cycles per orientation (default 1)")
    parser.add_argument(
        "--amplitude-a",
        type=finite_float,
        default=None,
        help="base coil current amplitude, A (default: the scenario's)",
    )
    parser.add_argument("--seed", type=int, default=None, help="noise seed (default: the scenario's)")
    parser.add_argument("--out", default=None, help="write the cycles to this new .npz file")
    parser.add_argument("--force", action="store_true", help="replace an existing --out file")
    parser.add_argument("--fit", action="store_true", help="fit each ring-down and print the frequencies")


def run(args) -> int:
    with input_file(args.scenario):
        scenario = load_scenario(args.scenario)
        if args.seed is not None:
            scenario = scenario.replace(seed=args.seed)
        device = SimulatedDevice(scenario)
    if args.out:  # after loading: the files the scenario pulled in are inputs too
        check_output(args.out, [args.scenario], args.force)
    excitation = scenario.excitation
    amplitude = excitation.amplitude_a if args.amplitude_a is None else args.amplitude_a
    if amplitude == 0.0:
        raise ValueError("--amplitude-a 0: no current, no swing, no ring-down to simulate; give the coils' amplitude")
    ranges.check("coil_current_a", amplitude, "--amplitude-a")
    angles = [math.degrees(scenario.pose.theta0_rad)] if args.theta0_deg is None else args.theta0_deg
    records = []
    for theta0_deg in angles:
        for _ in range(args.repeats):
            record = simulate_cycle(
                device,
                math.radians(theta0_deg),
                amplitude,
                excitation.frequency_hz,
                excitation.excite_s,
                excitation.ringdown_s,
                settle_s=excitation.gap_s,
            )
            records.append(record)
            if args.fit:
                fit = fit_cycle(record, scenario)
                print(f"θ0 = {theta0_deg:7.2f}°: {_compare(fit, record)}")
    if args.out:
        scenario_yaml = yaml.safe_dump(scenario.to_dict(), sort_keys=False)
        with writing([args.out], [args.scenario], args.force) as outputs:
            with open(outputs.temporaries[0], "wb") as handle:
                np.savez_compressed(handle, **cycles_npz(records, scenario_yaml))
        print(f"{outputs.report()}: {len(records)} cycles")
    return 0


def _compare(fit, record) -> str:
    """The fit against the truth: f(A(t)) of the full potential averaged over the fitted window."""
    if not fit.ok:
        return fit.report()
    truth = record.ringdown_frequency_hz(fit.duration_s)
    return (
        f"{fit.report()}; truth {truth:.6f} Hz from {math.degrees(record.ringdown_amplitude_rad()):.1f}° "
        f"(fit − truth = {(fit.frequency_hz - truth) * 1e3:+.3f} mHz)"
    )
