"""``mows fit BAG``: fit every ring-down in a bag the driver recorded, offline.

The bag's ``/mows/raw`` blocks and ``/mows/excitation`` phases go through the estimator node's
own stream core and fit settings (:mod:`mows.lab.data.ringdowns`): each recorded RINGDOWN phase
(tuning ones skipped unless ``--tuning``) is cut out by its device stamps and fitted with the
lever-aware signal model of the fluxgate pair the options describe (``--paper-model`` for Eq.
S11). One line per ring-down; ``--csv`` writes a model-lab table (theta0_deg, f_hz, f_std_hz,
t_s, sweep, amplitude_deg, damping_per_s, duration_s, and the marker mows_table_format of the
project's own tables) of the OK fits, ready for ``mows lab`` with ``--reference`` (no file when
none is OK). A sweep measures each orientation once (:func:`mows.sweep.record.sweep_numbers`).
``--temperature-log`` joins a logger's CSV (``t_s`` on the device clock, ``temperature_k``) as
the column ``temperature_k`` at each ring-down's start (:func:`mows.lab.data.readers.logged_at`).
The CSV is never written into the bag nor over an existing file (unless
``--force``), and appears whole or not at all (:mod:`mows.records.files`).

A bag of several probes sharing each window (docs/multi_probe.md: its excitations list the
probes they ring) is fitted jointly with ``--probes SPEC``, the estimator's ``probes``
parameter (YAML: probe id → f00 in Hz, a probe file, or ``{f00_hz, f00_std_hz, probe_file,
position_m}``; the probe files it names are inputs): one line per ring-down and probe, and the
table's column ``probe`` says each row's probe, each probe's start swings from its own fits
(:func:`mows.lab.data.readers.start_amplitudes_rad`). A probe a window lists but ``--probes``
does not is a failed fit naming it. Without ``--probes`` such a bag is refused in one line
naming its probes (fitting one probe per window would bias each probe's frequency by its
neighbours').
"""

import math
import os
import sys

import numpy as np

from mows.cli.inputs import finite_float, input_file, non_negative_float, renamed_option, sensor_length_m
from mows.estimate.ringdown import COIL_OFF_SKIP_S
from mows.estimate.settings import FitParameters
from mows.estimate.stream import Estimated, FitSettings
from mows.lab.data.intake import tool_table
from mows.lab.data.readers import is_bag, logged_at, start_amplitudes_rad
from mows.lab.data.ringdowns import BagFitting, fit_bag
from mows.lab.data.table import PROBE
from mows.physics.fluxgate import PAPER_DISTANCE_M, PAPER_SPACING_M
from mows.physics.probe import PAPER_PROBE, Probe
from mows.records.files import check_output, writing
from mows.records.stamps import NS_PER_S
from mows.sweep.record import SweepPoint, SweepRecord, sweep_numbers


def add_arguments(parser) -> None:
    parser.add_argument("bag", help="a rosbag2 directory (or .mcap) recorded by the driver (record_path)")
    add_bag_arguments(parser)
    parser.add_argument("--csv", help="write the OK fits as a model-lab table (a new file)")
    parser.add_argument(
        "--temperature-log",
        metavar="CSV",
        help="a logger's CSV of t_s (device clock, s) and temperature_k, joined to the --csv table's rows",
    )
    parser.add_argument("--force", action="store_true", help="replace an existing --csv file (never the bag)")


def add_bag_arguments(parser) -> None:
    """How a recorded bag's ring-downs are found and fitted (also ``mows lab ringdown``)."""
    parser.add_argument("--probe", help="probe constants YAML (default: the paper's probe)")
    parser.add_argument("--tuning", action="store_true", help="also fit the tuning ring-downs")
    parser.add_argument(
        "--probes",
        default="",
        metavar="SPEC",
        help="the probes sharing each window, fitted jointly: the estimator's probes parameter, YAML "
        "{ID: F00_HZ | PROBE_FILE | {f00_hz, f00_std_hz, probe_file, position_m}, ...} (docs/multi_probe.md)",
    )
    add_fit_arguments(parser)


def add_fit_arguments(parser) -> None:
    """How a bag's ring-downs are fitted (the estimator node's parameters of the same names)."""
    parser.add_argument("--raw-topic", default="/mows/raw")
    parser.add_argument("--excitation-topic", default="/mows/excitation")
    parser.add_argument("--paper-model", action="store_true", help="fit Eq. S11 (a magnet turning in place)")
    parser.add_argument(
        "--coil-off-skip-s", type=non_negative_float, default=COIL_OFF_SKIP_S, help="samples skipped after coil-off, s"
    )
    renamed_option(parser, "--settle-s", "--coil-off-skip-s")
    parser.add_argument(
        "--sensor-distance-m",
        type=sensor_length_m,
        default=PAPER_DISTANCE_M,
        help="probe to near fluxgate along --sensor-direction, m (as the estimator's parameter)",
    )
    parser.add_argument("--sensor-spacing-m", type=sensor_length_m, default=PAPER_SPACING_M, help="fluxgate spacing, m")
    parser.add_argument(
        "--sensor-direction",
        type=finite_float,
        nargs=3,
        metavar=("X", "Y", "Z"),
        default=FitParameters.sensor_direction,
        help="the line from the probe through both fluxgates in the rotation plane's frame (z: its normal)",
    )


def run(args) -> int:
    inputs = [args.bag] + [path for path in (args.probe, args.temperature_log) if path]
    if os.path.isfile(args.bag) and not is_bag(args.bag):
        raise ValueError(
            f"{args.bag} is not a bag (a bag is a directory or an .mcap file): "
            "a table of fits is read by mows lab compare / report"
        )
    if args.csv:
        check_output(args.csv, inputs, args.force)
    probe = Probe.from_yaml(args.probe) if args.probe else PAPER_PROBE
    how = bag_fitting(args)
    settings = fit_settings(how, probe)
    with input_file(args.bag):
        fits = list(fit_bag(args.bag, settings, how))
        check_ringdowns(args.bag, fits, how)
    for estimated in fits:
        print(f"{_heading(estimated)}: {estimated.fit.report()}")
    ok = [estimated for estimated in fits if estimated.fit.ok]
    print(f"{len(ok)} of {len(fits)} {_fitted(fits)}")
    if args.csv and ok:
        with writing([args.csv], inputs, args.force) as outputs:
            named = bool(how.parameters.probes.strip())
            notes = write_table(outputs.temporaries[0], ok, probe, named, args.temperature_log)
        print(f"{outputs.report()}: {len(ok)} rows")
        for note in notes:
            print(f"note: {note}")
    elif args.csv:
        print(f"mows fit: no ring-down fitted: {args.csv} not written", file=sys.stderr)
    return 0


def _heading(estimated: Estimated) -> str:
    """Its window and probe, at the probe's own θ0."""
    window = estimated.window
    return (
        f"cycle {window.cycle_id} repeat {window.repeat_index} probe {estimated.probe_id} "
        f"θ0 {math.degrees(estimated.fit.theta0_rad):7.2f}°"
    )


def _fitted(fits: list[Estimated]) -> str:
    """What the count counts: ring-downs where each held one probe, else probes' fits in so many ring-downs."""
    windows = len({id(estimated.window) for estimated in fits})
    return "ring-downs fitted" if windows == len(fits) else f"probes' fits OK in {windows} ring-downs"


def bag_fitting(args) -> BagFitting:
    """The bag arguments (:func:`add_fit_arguments`, ``--tuning``, ``--probes``) as the core's
    settings of the estimator's parameters of the same names."""
    parameters = FitParameters(
        lever_aware=not args.paper_model,
        sensor_distance_m=args.sensor_distance_m,
        sensor_direction=tuple(args.sensor_direction),
        sensor_spacing_m=args.sensor_spacing_m,
        coil_off_skip_s=args.coil_off_skip_s,
        probes=args.probes,
    )
    return BagFitting(args.raw_topic, args.excitation_topic, args.tuning, parameters)


def fit_settings(how: BagFitting, probe: Probe) -> FitSettings:
    """The estimator's fit settings of ``how`` for ``probe``; ValueError naming the option that
    is wrong (``--probes``, ``--sensor-direction``), before any ring-down is read."""
    try:
        how.parameters.fluxgate_pair()
    except ValueError as error:
        raise ValueError(f"--sensor-direction: {error}") from None
    try:
        return how.parameters.fit_settings(probe)
    except ValueError as error:
        raise ValueError(f"--probes: {error}") from None


def check_ringdowns(path, fits: list[Estimated], how: BagFitting) -> None:
    """ValueError when the bag holds no ring-down to fit, or ``--coil-off-skip-s`` skips all of each."""
    if not fits:
        raise ValueError(
            f"{path} holds no ring-down: no RINGDOWN phase on {how.excitation_topic} with samples on "
            f"{how.raw_topic}{'' if how.tuning else ' (tuning ones skipped: --tuning)'}"
        )
    longest = max(estimated.window.duration_s for estimated in fits)
    skip_s = how.parameters.coil_off_skip_s
    if skip_s >= longest:
        raise ValueError(f"--coil-off-skip-s {skip_s:g} s skips the whole of every ring-down (longest {longest:g} s)")


def write_table(path, fits: list[Estimated], probe: Probe, named: bool, temperature_log=None) -> list[str]:
    """The OK fits as a model-lab table, numbered by sweep and with ``temperature_log`` joined
    where given (module docstring); returns notes of how the start swings were found.

    Every ring-down of one probe starts at the housing stop
    (:meth:`mows.sweep.record.SweepRecord.start_swings_rad`: the rest angle from the sweep's field
    where one static field describes the fits, else from each fit). Fits of probes named by
    ``--probes`` (``named``), whose multi-tone excitation need not swing them to the stop, are
    marked by the column ``probe`` and each probe's start swings come from its own fits, as those
    the estimator recorded
    (:func:`mows.lab.data.readers.start_amplitudes_rad`). The table is marked as the project's
    own (:func:`mows.lab.data.intake.tool_table`)."""
    record = SweepRecord(
        [
            SweepPoint.from_fit(
                e.fit, e.estimate.frequency_shift_hz, e.estimate.frequency_shift_std_hz, e.window.start_ns / NS_PER_S
            )
            for e in fits
        ]
    )
    if named:
        probe_ids = np.array([e.probe_id for e in fits], float)
        start, notes = start_amplitudes_rad([e.fit for e in fits], np.zeros(len(fits)), probe.theta_stop_rad, probe_ids)
        columns = record.table_columns(start) | {PROBE: probe_ids}
    else:
        start, notes = record.start_swings_rad(probe)
        columns = record.table_columns(start)
    columns["sweep"] = _sweeps(fits).astype(float)
    if temperature_log is not None:
        with input_file(temperature_log, "temperature log"):
            columns["temperature_k"] = logged_at(
                temperature_log, np.array([e.window.start_ns / NS_PER_S for e in fits])
            )
    tool_table(columns, str(path)).to_csv(path)
    return notes


def _sweeps(fits: list[Estimated]) -> np.ndarray:
    """Each fit's sweep by its window's orientation; the probes of one window share it."""
    first = [i for i, e in enumerate(fits) if i == 0 or e.window is not fits[i - 1].window]
    numbers = sweep_numbers(np.array([fits[i].window.theta0_rad for i in first]))
    return np.repeat(numbers, np.diff([*first, len(fits)]))
