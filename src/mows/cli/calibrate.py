"""``mows calibrate``: a new probe's constants from a supply sweep, written as a probe file.

Input (one of):

* ``TABLE`` — a CSV of ring-down fits with the columns ``supply_current_a``, ``theta0_deg``,
  ``f_hz``, ``f_std_hz``, ``damping_per_s``, ``duration_s``, ``amplitude_deg``,
  ``start_offset_s`` and ``gradient_wiring`` (0: the homogeneous wiring, 1: the gradient one);
  ``--table`` writes this format;
* ``BAG`` — a bag the driver recorded (``record_path``) while the calibration action ran: its
  ring-downs fitted as the estimator fits them, each at the supply current the driver's
  ``/mows/supply`` states say held steady over it (:mod:`mows.cli.calibrate_bag`), all of the
  homogeneous wiring; the same points, hence the same constants, as the action's. A bag
  without supply states (recorded before the driver published them) is refused, exit status 2;
* ``--simulate`` — run the calibration schedule (:mod:`mows.sweep.calibration.schedule`) on the
  simulated device of ``--scenario`` in simulated device time, and compare with its truth.

The supply's field (and gradient) per ampere at the probe come from the ``supply`` section of
``--scenario`` (and ``--gradient-scenario``); the magnet's moment, mass and the housing stop from
``--probe`` (the nominal probe: data sheet and scale). The fit is
:func:`mows.estimate.calibration.fit.calibrate_probe`; it finds each pair's polarity from the
data (``--polarity`` states it instead) and refuses implausible constants by name.

Supply currents beyond the supply's cap and frequencies far from the nominal probe's f00 are
refused before any fit (a table in mA or kHz). ``-o`` and ``--table`` are written together or
not at all, never over an input, over an existing file only with ``--force``
(:func:`mows.records.files.writing`; docs/cli.md).
"""

from __future__ import annotations

import dataclasses
import datetime
import math
import warnings
from collections.abc import Mapping

import numpy as np

from mows.cli.calibrate_bag import SUPPLY_TOPIC, bag_points
from mows.cli.fit import add_fit_arguments
from mows.cli.inputs import check_frequencies, finite_float, input_file, positive_int
from mows.device.cycle.phases import CycleSettings, Phase, PhaseEvent
from mows.device.stream.device_time import DeviceTimeLoop, scheduled_device
from mows.estimate.calibration.constants import CalibrationPoint, KnownConstants
from mows.estimate.calibration.fit import calibrate_probe
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, fit_ringdown
from mows.estimate.segments import RingdownWindow, SegmentAssembler, fit_segment
from mows.lab.data.readers import is_bag, load_table
from mows.lab.data.table import MeasurementTable, rows_text
from mows.physics.coils import CurrentCap
from mows.physics.probe import PAPER_PROBE, Probe
from mows.physics.ringdown_average import start_swing_rad
from mows.records.files import check_outputs, writing
from mows.sim.scenario import load_scenario
from mows.sweep.calibration.schedule import (
    GRADIENT_WIRING,
    CalibrationOutcome,
    CalibrationPlan,
    CalibrationSchedule,
    SetSupply,
    default_currents_a,
    scenario_wirings,
)

SUPPLY_SETTLE_S = 0.5  # the probe rings after a supply step: wait before the next cycle
SEGMENT_BUFFER_S = 5.0  # the stream kept to cut the ring-downs from, as the estimator keeps it

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
    parser.set_defaults(tuning=False, bag_defaults=bag_defaults, **dict.fromkeys(BAG_OPTIONS))


def run(args) -> int:
    inputs = [path for path in (args.input, args.probe, args.scenario, args.gradient_scenario) if path]
    outputs = [args.output] + ([args.table] if args.table else [])
    check_outputs(outputs, inputs, args.force)
    _source_options(args)
    nominal = Probe.from_yaml(args.probe) if args.probe else PAPER_PROBE
    scenario = _scenario(args.scenario)
    gradient = _scenario(args.gradient_scenario) if args.gradient_scenario else None
    wirings = scenario_wirings(scenario, gradient)
    field_wiring = next(iter(wirings))  # the scenario's own supply: the homogeneous wiring
    limits = scenario.supply.limits
    if args.simulate:
        args.currents_a = args.currents_a or list(default_currents_a(limits))
        _check_currents(args.currents_a, limits, "--currents-a")
        for supply in [scenario.supply] + ([gradient.supply] if gradient else []):
            CalibrationPlan(tuple(args.currents_a)).check_supply(supply.limits.min_current_a, supply.limits.cap_a)
        points, failed = simulated_points(scenario, gradient, nominal, field_wiring, args)
    elif args.input and is_bag(args.input):
        with input_file(args.input, "bag"):
            points, failed, unknown = bag_points(args.input, nominal, field_wiring, args)
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


# --- the simulated calibration ------------------------------------------------------------
def simulated_points(scenario, gradient, nominal: Probe, field_wiring: str, args) -> tuple[list, dict]:
    plan = CalibrationPlan(tuple(args.currents_a), repeats=args.repeats, wiring=field_wiring)
    seed = scenario.seed if args.seed is None else args.seed
    outcome = _succeeded(simulate_calibration(scenario.replace(seed=seed), plan, nominal))
    points, failed = list(outcome.points), dict(outcome.failed)
    if gradient is not None:
        plan = CalibrationPlan(tuple(args.currents_a), repeats=args.repeats, wiring=GRADIENT_WIRING)
        more = _succeeded(simulate_calibration(gradient.replace(seed=seed + 1), plan, nominal))
        points += more.points
        failed.update(more.failed)
    return points, failed


def _succeeded(outcome: CalibrationOutcome) -> CalibrationOutcome:
    """The outcome of a schedule that ran to its end; ValueError with its reason otherwise."""
    if not outcome.success:
        raise ValueError(f"the simulated calibration stopped: {outcome.message}")
    return outcome


def simulate_calibration(scenario, plan: CalibrationPlan, nominal: Probe, on_feedback=None) -> CalibrationOutcome:
    """Run :class:`CalibrationSchedule` on the simulated device of ``scenario`` in device time.

    The supply ramps and the cycles run as the driver runs them
    (:class:`mows.device.stream.device_time.DeviceTimeLoop`: the supply's cap, slew and resolution;
    the driver's cycle with its default settings but the scene's excitation), each cycle driven
    where the paper's tuning leaves the drive (:func:`_resonance_hz`), and every measurement
    ring-down is cut from the stream and fitted as the estimator does, with the lever-aware
    pickup of the **nominal** probe (the true lever is what is being calibrated). ValueError if
    the schedule does not end at zero current.
    """
    excitation = scenario.excitation
    settings = CycleSettings(
        excitation_current_a=excitation.amplitude_a, excite_s=excitation.excite_s, ringdown_s=excitation.ringdown_s
    )
    fits = _NominalFits(scenario.sensors.pair, nominal)
    device = scheduled_device(scenario, CurrentCap(), np.random.default_rng(scenario.seed))
    loop = DeviceTimeLoop(device, settings, fit=fit_ringdown, on_block=fits.block, on_event=fits.event)
    schedule = CalibrationSchedule(plan)
    pending = [schedule.start()]
    while pending:
        step = pending.pop(0)
        for feedback in step.feedback:
            if on_feedback:
                on_feedback(feedback)
        if step.outcome is not None:
            if device.device.field_current_a != 0.0:
                raise ValueError(f"the supply is at {device.device.field_current_a} A after the calibration")
            return step.outcome
        for action in step.actions:
            if isinstance(action, SetSupply):
                refused = loop.ramp_supply(action.current_a, SUPPLY_SETTLE_S)
                pending.append(schedule.on_supply(not refused, refused))
                continue
            tuned = _resonance_hz(device.device, action.theta0_rad)
            outcome = loop.run_cycle(dataclasses.replace(action, frequency_hz=tuned, tuning_steps=0))
            pending += [schedule.on_fit(fit) for fit in fits.take()]
            pending.append(schedule.on_cycle_done(outcome.success, outcome.message))
    raise RuntimeError("the calibration schedule stopped without an outcome")


def _resonance_hz(device, theta0_rad: float) -> float:
    """The simulated probe's small-amplitude resonance at ``theta0_rad`` in the present supply
    field: where the paper's tuning leaves the drive. The stage is turned there first (between
    cycles, the coils off); the cycle's own turn then finds it there."""
    device.set_orientations([theta0_rad])
    return device.expected_frequency_hz()


class _NominalFits:
    """The measurement ring-downs announced on the stream, cut and fitted as the estimator fits
    them with the lever-aware pickup of the ``nominal`` probe seen by ``pair``."""

    def __init__(self, pair, nominal: Probe):
        self.pair, self.nominal = pair, nominal
        self.assembler = SegmentAssembler(SEGMENT_BUFFER_S)
        self._fits: list = []

    def block(self, block) -> None:
        self._fits += [self._fit(segment) for segment in self.assembler.add_block(block.samples)]

    def event(self, event: PhaseEvent) -> None:
        if event.phase == Phase.RINGDOWN and not event.tuning:
            window = RingdownWindow(
                event.stamp_ns,
                event.planned_duration_s,
                event.cycle_id,
                event.repeat_index,
                event.theta0_rad,
                event.frequency_hz,
            )
            self._fits += [self._fit(segment) for segment in self.assembler.announce(window)]

    def take(self) -> list:
        """The fits made since the last call."""
        fits, self._fits = self._fits, []
        return fits

    def _fit(self, segment):
        options = FitOptions.lever_aware(self.pair, self.nominal, segment.window.theta0_rad)
        return fit_segment(segment, options, COIL_OFF_SKIP_S, self.nominal.damping_per_s)


def compare_with_truth(calibration, truth: Probe) -> str:
    rows = [
        ("f00_hz", truth.f00_hz),
        ("beta0_hz_per_t", truth.beta0_hz_per_t),
        ("spring_nm_per_rad", truth.spring_nm_per_rad),
        ("inertia_kgm2", truth.inertia_kgm2),
        ("lever_m", truth.lever_m),
    ]
    lines = ["calibrated against true constants:"]
    for name, true in rows:
        value, std = calibration.value(name), calibration.std(name)
        lines.append(
            f"  {name:18s} {value:.6g} ± {std:.2g}  true {true:.6g}  "
            f"({(value / true - 1) * 100:+.4f} %, {(value - true) / std:+.2f} σ)"
        )
    return "\n".join(lines)


# --- tables and bags ----------------------------------------------------------------------
#: A cantilever's swing is a fraction of a turn: a θmax of half a turn or more is no angle in degrees.
MAX_AMPLITUDE_DEG = 180.0
TABLE_COLUMNS = (
    "supply_current_a",
    "damping_per_s",
    "duration_s",
    "amplitude_deg",
    "start_offset_s",
    "gradient_wiring",
)


def write_points(path, points, field_wiring: str, stop_rad: float) -> None:
    """The calibration's points as a table. ``amplitude_deg`` is each fit's θmax, or where the
    fit did not determine it the stop less its rest offset (the start swing's rule), flagged 0
    in ``amplitude_fitted`` so that :func:`read_points` reads it back as not measured."""
    fitted = np.array([math.isfinite(p.amplitude_rad) for p in points])
    columns = {
        "theta0_deg": np.degrees([p.theta0_rad for p in points]),
        "f_hz": np.array([p.frequency_hz for p in points]),
        "f_std_hz": np.array([p.frequency_std_hz for p in points]),
        "supply_current_a": np.array([p.supply_current_a for p in points]),
        "damping_per_s": np.array([p.damping_per_s for p in points]),
        "duration_s": np.array([p.duration_s for p in points]),
        "amplitude_deg": np.degrees(_start_amplitudes_rad(points, stop_rad)),
        "amplitude_fitted": fitted.astype(float),
        "start_offset_s": np.array([p.start_offset_s for p in points]),
        "gradient_wiring": np.array([float(p.wiring != field_wiring) for p in points]),
    }
    MeasurementTable(columns, str(path)).to_csv(path)


def _start_amplitudes_rad(points, stop_rad: float) -> np.ndarray:
    """Each point's θmax, or where its fit did not determine it the stop less the fit's rest
    offset (0 where that is not determined either): a swing the physics allows, never NaN."""
    amplitude = np.array([p.amplitude_rad for p in points], float)
    rest = np.nan_to_num(np.array([p.rest_offset_rad for p in points], float))
    return np.where(np.isfinite(amplitude), amplitude, np.nan_to_num(start_swing_rad(stop_rad, rest)))


def _table_columns(path) -> Mapping:
    """The table's columns, every calibration column a finite number in every row; a θmax the
    fits did not determine (NaN in ``amplitude_deg``) is read as not measured, as
    :func:`write_points` flags it (``amplitude_fitted`` 0). A file that is no plain CSV of numbers
    is read by the lab's reader, which says what is wrong with it."""
    columns = _numeric_columns(path)
    if columns is None:
        return load_table(path).columns
    amplitude = columns.pop("amplitude_deg", None)  # checked here: NaN is a θmax not measured
    if amplitude is not None:
        flagged = columns.get("amplitude_fitted", np.ones(amplitude.shape))
        columns["amplitude_fitted"] = (np.isfinite(amplitude) & (flagged != 0)).astype(float)
        non_positive = np.flatnonzero(np.isfinite(amplitude) & (amplitude <= 0))
        if len(non_positive):
            raise ValueError(f"column 'amplitude_deg' must be > 0: not so in {rows_text(non_positive)}")
        beyond = np.flatnonzero(np.isfinite(amplitude) & (amplitude >= MAX_AMPLITUDE_DEG))
        if len(beyond):
            raise ValueError(
                f"column 'amplitude_deg' must be below {MAX_AMPLITUDE_DEG:g}° (a swing in degrees): "
                f"not so in {rows_text(beyond)}"
            )
    wiring = columns.get("gradient_wiring", np.zeros(0))
    flags = np.flatnonzero(np.isfinite(wiring) & (wiring != 0) & (wiring != 1))
    if len(flags):
        raise ValueError(
            f"column 'gradient_wiring' is 0 (field pair) or 1 (gradient pair): not so in {rows_text(flags)}"
        )
    for name in ("theta0_deg", "f_hz", "f_std_hz", *TABLE_COLUMNS):
        bad = np.flatnonzero(~np.isfinite(columns[name])) if name in columns else ()
        if len(bad):
            raise ValueError(f"column '{name}' is not a finite number in {rows_text(bad)}")
    checked = dict(load_table(columns).columns)
    if amplitude is not None:
        checked["amplitude_deg"] = amplitude
    return checked


def _numeric_columns(path) -> dict | None:
    """Every column of a CSV of numbers (NaN allowed), or None for any other file."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            values = np.genfromtxt(path, delimiter=",", names=True, encoding="utf-8-sig", invalid_raise=True)
        except (ValueError, IndexError):  # IndexError: an empty file, which numpy does not name
            return None
    names = values.dtype.names or ()
    return {name: np.atleast_1d(values[name]).astype(float) for name in names} or None


def read_points(path, field_wiring: str) -> list:
    """Calibration points from a calibration table (CSV)."""
    c = _table_columns(path)
    missing = [name for name in TABLE_COLUMNS if name not in c]
    if missing:
        raise ValueError(f"{path}: a calibration table needs the columns {list(TABLE_COLUMNS)}; missing {missing}")
    return [
        CalibrationPoint(
            GRADIENT_WIRING if c["gradient_wiring"][i] else field_wiring,
            float(c["supply_current_a"][i]),
            math.radians(c["theta0_deg"][i]),
            float(c["f_hz"][i]),
            float(c["f_std_hz"][i]),
            math.radians(c["amplitude_deg"][i]) if c.get("amplitude_fitted", np.ones(len(c["f_hz"])))[i] else math.nan,
            float(c["damping_per_s"][i]),
            float(c["duration_s"][i]),
            float(c["start_offset_s"][i]),
        )
        for i in range(len(c["f_hz"]))
    ]
