"""``mows calibrate``: a new probe's constants from a supply sweep, written as a probe file.

Input (one of):

* ``TABLE`` — a CSV of ring-down fits with the columns ``supply_current_a``, ``theta0_deg``,
  ``f_hz``, ``f_std_hz``, ``damping_per_s``, ``duration_s``, ``amplitude_deg``,
  ``start_offset_s`` and ``gradient_wiring`` (0: the homogeneous wiring, 1: the gradient one);
  ``--table`` writes this format (:mod:`mows.lab.data.calibration_table`);
* ``BAG`` — a bag the driver recorded (``record_path``) while the calibration action ran: its
  ring-downs fitted as the estimator fits them, each at the supply current the driver's
  ``/mows/supply`` states say held steady over it (:mod:`mows.cli.calibrate_bag`), all of the
  homogeneous wiring; the same points, hence the same constants, as the action's. A bag
  without supply states (recorded before the driver published them) is refused, exit status 2;
* ``--simulate`` — run the calibration schedule (:mod:`mows.sweep.calibration.schedule`) on the
  simulated device of ``--scenario`` in simulated device time
  (:mod:`mows.sweep.calibration.simulated`), and compare with its truth.

The supply's field (and gradient) per ampere at the probe come from the ``supply`` section of
``--scenario`` (and ``--gradient-scenario``); the magnet's moment, mass and the housing stop from
``--probe`` (the nominal probe: data sheet and scale). The fit is
:func:`mows.estimate.calibration.fit_constants.calibrate_probe`; it finds each pair's polarity from the
data (``--polarity`` states it instead) and refuses implausible constants by name.

Supply currents beyond the supply's cap and frequencies far from the nominal probe's f00 are
refused before any fit (a table in mA or kHz). ``-o`` and ``--table`` are written together or
not at all, never over an input, over an existing file only with ``--force``
(:func:`mows.records.files.writing`; docs/cli.md).
"""

from __future__ import annotations

import datetime
import math

from mows.cli.calibrate_bag import SUPPLY_TOPIC, bag_points
from mows.cli.fit_bag import add_fit_arguments, bag_fitting, fit_settings
from mows.cli.inputs import finite_float, input_file, positive_int
from mows.estimate.calibration.constants import KnownConstants
from mows.estimate.calibration.fit_constants import calibrate_probe
from mows.lab.data.calibration_table import read_points, write_points
from mows.lab.data.readers import is_bag
from mows.lab.data.scale import check_frequencies
from mows.physics.probe import PAPER_PROBE, Probe
from mows.records.files import check_outputs, writing
from mows.sim.scenario import load_scenario
from mows.sweep.calibration.schedule import GRADIENT_WIRING, CalibrationPlan, default_currents_a, scenario_wirings
from mows.sweep.calibration.simulated import compare_with_truth, simulated_points

#: The options that shape --simulate's calibration alone (by argparse name), and their defaults
#: (the currents' default follows the supply's polarity: ``default_currents_a``).
SIMULATION_OPTIONS = {"currents_a": None, "repeats": 1, "seed": None}
#: The options that shape a BAG's calibration alone (their defaults are the parser's).
BAG_OPTIONS = (
    "supply_topic",
    "raw_topic",
    "excitation_topic",
    "paper_model",
    "coil_off_skip_s",
    "sensor_distance_m",
    "sensor_spacing_m",
    "sensor_direction",
)


def add_arguments(parser) -> None:
    parser.add_argument("input", nargs="?", help="a calibration table (CSV; --table writes one) or a driver's bag")
    parser.add_argument("-o", "--output", required=True, help="the probe file to write (YAML)")
    parser.add_argument("--probe", help="nominal probe YAML: moment, magnet mass, housing stop (default: paper's)")
    parser.add_argument("--scenario", default="calibration", help="scenario whose supply section is the wiring")
    parser.add_argument("--gradient-scenario", help="scenario of the gradient wiring (anti-Helmholtz)")
    parser.add_argument(
        "--environment-field-t",
        type=finite_float,
        nargs=3,
        metavar=("BX", "BY", "BZ"),
        help="reference magnetometer reading at the probe with the supply at zero, T",
    )
    parser.add_argument("--hardware-id", default="", help="written to the probe file (default: the scenario)")
    parser.add_argument("--simulate", action="store_true", help="calibrate the scenario's simulated probe")
    parser.add_argument(
        "--currents-a",
        type=finite_float,
        nargs="+",
        help="--simulate: the supply currents, A (default: 0, ±0.5 … ±2; on a unipolar supply 0 … 2, "
        "the field's other sign from θ0 = 180°)",
    )
    parser.add_argument("--repeats", type=positive_int, help="--simulate: ring-downs per cycle (default: 1)")
    parser.add_argument("--seed", type=int, help="--simulate: noise seed (default: the scenario's)")
    parser.add_argument("--table", help="also write the calibration points as a table (CSV)")
    parser.add_argument("--force", action="store_true", help="replace existing output files (never an input)")
    parser.add_argument(
        "--polarity",
        nargs="+",
        metavar="PAIR=SIGN",
        help="the sign of a pair's current as wired: field=-1, gradient=-1 (default: found from the data)",
    )
    parser.add_argument("--supply-topic", default=SUPPLY_TOPIC, help="BAG: the driver's supply states")
    add_fit_arguments(parser)  # BAG: how its ring-downs are fitted (as the estimator's parameters)
    # None marks an option not given (refused by name without a BAG); its default comes in later
    bag_defaults = {name: parser.get_default(name) for name in BAG_OPTIONS}
    parser.set_defaults(tuning=False, probes="", bag_defaults=bag_defaults, **dict.fromkeys(BAG_OPTIONS))


def run(args) -> int:
    inputs = [path for path in (args.input, args.probe, args.scenario, args.gradient_scenario) if path]
    outputs = [args.output] + ([args.table] if args.table else [])
    _source_options(args)
    nominal = Probe.from_yaml(args.probe) if args.probe else PAPER_PROBE
    scenario = _scenario(args.scenario)
    gradient = _scenario(args.gradient_scenario) if args.gradient_scenario else None
    check_outputs(outputs, inputs, args.force)  # the files the scenarios pulled in are inputs too
    wirings = scenario_wirings(scenario, gradient)
    field_wiring = next(iter(wirings))  # the scenario's own supply: the homogeneous wiring
    limits = scenario.supply.limits
    if args.simulate:
        args.currents_a = args.currents_a or list(default_currents_a(limits))
        _check_currents(args.currents_a, limits, "--currents-a")
        for supply in [scenario.supply] + ([gradient.supply] if gradient else []):
            CalibrationPlan(tuple(args.currents_a)).check_supply(supply.limits.min_current_a, supply.limits.cap_a)
        plan = CalibrationPlan(tuple(args.currents_a), repeats=args.repeats, wiring=field_wiring)
        seed = scenario.seed if args.seed is None else args.seed
        points, failed = simulated_points(scenario, gradient, nominal, plan, seed)
    elif args.input and is_bag(args.input):
        how = bag_fitting(args)
        settings = fit_settings(how, nominal)
        with input_file(args.input, "bag"):
            points, failed, unknown = bag_points(args.input, settings, field_wiring, args.supply_topic, how)
        if unknown:
            print(f"{unknown} ring-down(s) at no steady supply current (ramping, or before it was set) left out")
    elif args.input:
        with input_file(args.input, "calibration table"):
            points, failed = read_points(args.input, field_wiring), {}
            _check_currents([p.supply_current_a for p in points], limits, "supply_current_a")
            check_frequencies([p.frequency_hz for p in points], nominal, "f_hz")
    else:
        raise ValueError("give a TABLE or BAG, or --simulate")
    known = KnownConstants.of(nominal, args.environment_field_t)
    polarity = _polarity(args.polarity, field_wiring)
    calibration = calibrate_probe(points, wirings, known, field_wiring, failed, nominal.lever_m, polarity)
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    record = calibration.record(date, args.hardware_id or scenario.name)
    with writing(outputs, inputs, args.force) as written:
        written.temporaries[0].write_text(calibration.probe().yaml_text(record))
        if args.table:
            write_points(written.temporaries[1], points, field_wiring, nominal.theta_stop_rad)
    print(calibration.report())
    if args.simulate:
        print(compare_with_truth(calibration, scenario.probe))
    print(written.report())
    return 0


def _scenario(name):
    with input_file(name, "scenario"):
        return load_scenario(name)


def _check_currents(currents_a, limits, what: str) -> None:
    """ValueError naming the first current beyond the supply's cap (a table in mA, a typo)."""
    for i, current in enumerate(currents_a):
        if not (math.isfinite(current) and abs(current) <= limits.cap_a):
            where = f" (ring-down {i + 1})" if what == "supply_current_a" else ""
            raise ValueError(
                f"{what} = {current:g} A{where} is outside the supply's cap of ±{limits.cap_a:g} A "
                "(currents in mA? the cap is the scenario's supply cap_a)"
            )


def _polarity(given, field_wiring: str) -> dict:
    """``--polarity field=-1 gradient=+1`` as wiring name → sign."""
    names = {"field": field_wiring, "gradient": GRADIENT_WIRING}
    polarity = {}
    for item in given or ():
        pair, _, sign = item.partition("=")
        if pair not in names or sign not in ("+1", "1", "-1"):
            raise ValueError(f"--polarity {item!r}: expected field=+1, field=-1, gradient=+1 or gradient=-1")
        polarity[names[pair]] = -1 if sign == "-1" else 1
    return polarity


def _source_options(args) -> None:
    """An input with --simulate, or an option of a source not in use (--simulate, a BAG), is
    refused by name (it would be ignored); the options of the source in use that were not
    given take their defaults."""
    if args.simulate and args.input:
        raise ValueError(f"{args.input} and --simulate are two sources: give a TABLE or BAG, or --simulate")
    bag = bool(args.input) and is_bag(args.input)
    sources = (
        ("--simulate's", "add --simulate", args.simulate, SIMULATION_OPTIONS),
        ("a BAG's", "give a BAG", bag, args.bag_defaults),
    )
    for source, remedy, used, options in sources:
        given = [f"--{name.replace('_', '-')}" for name in options if getattr(args, name) is not None]
        if given and not used:
            verb, them = ("shape", "them") if len(given) > 1 else ("shapes", "it")
            raise ValueError(f"{', '.join(given)} {verb} only {source} calibration: drop {them} or {remedy}")
        for name, default in options.items():
            if getattr(args, name) is None:
                setattr(args, name, default)
