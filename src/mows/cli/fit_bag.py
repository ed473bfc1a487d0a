"""``mows fit BAG``: fit every ring-down in a bag the driver recorded, offline.

The bag's ``/mows/raw`` blocks and ``/mows/excitation`` phases go through the same path as in
the estimator node (:mod:`mows.estimate.segments`, :mod:`mows.estimate.ringdown`): each recorded RINGDOWN phase
(tuning ones skipped unless ``--tuning``) is cut out by its device stamps and fitted with the
lever-aware signal model of the paper's geometry (``--paper-model`` for Eq. S11). One line per
ring-down; ``--csv`` writes a model-lab table (theta0_deg, f_hz, f_std_hz, t_s, amplitude_deg,
damping_per_s, duration_s, and the marker mows_table_format of the project's own tables) of the
OK fits, ready for ``mows lab`` with ``--reference`` (no file when none is OK).
The CSV is never written into the bag nor over an existing file (unless ``--force``), and
appears whole or not at all (:mod:`mows.records.files`).

A bag of several probes sharing each window (docs/multi_probe.md: its excitations list the
probes they ring, or its recorded fits carry more than one ``probe_id``) is refused in one
line: fitting one probe per window would bias each probe's frequency by its neighbours', and
the joint fit needs the estimator's ``probes`` list, which this command does not take. The
estimator's own fits in such a bag are read, each probe apart, by ``mows lab compare BAG``.
"""

import dataclasses
import math
import os
import sys

from mows.cli.inputs import input_file, non_negative_float, renamed_option, sensor_length_m
from mows.estimate.ringdown import COIL_OFF_SKIP_S
from mows.lab.data.readers import is_bag
from mows.lab.data.ringdowns import BagFitting, fit_bag
from mows.lab.data.table import tool_table
from mows.physics.fluxgate import PAPER_DISTANCE_M, PAPER_SPACING_M
from mows.physics.probe import PAPER_PROBE, Probe
from mows.records.files import check_output, writing
from mows.records.stamps import NS_PER_S
from mows.sweep.record import SweepPoint, SweepRecord

# Fits that one static field describes this well are one sweep: its field gives each rest angle.
MAX_SWEEP_CHI2_DOF = 10.0


def add_arguments(parser) -> None:
    parser.add_argument("bag", help="a rosbag2 directory (or .mcap) recorded by the driver (record_path)")
    add_bag_arguments(parser)
    parser.add_argument("--csv", help="write the OK fits as a model-lab table (a new file)")
    parser.add_argument("--force", action="store_true", help="replace an existing --csv file (never the bag)")


def add_bag_arguments(parser) -> None:
    """How a recorded bag's ring-downs are found and fitted (also ``mows lab ringdown``)."""
    parser.add_argument("--probe", help="probe constants YAML (default: the paper's probe)")
    parser.add_argument("--tuning", action="store_true", help="also fit the tuning ring-downs")
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
        help="probe to near fluxgate along the plane's x axis, m (as the estimator's parameter)",
    )
    parser.add_argument("--sensor-spacing-m", type=sensor_length_m, default=PAPER_SPACING_M, help="fluxgate spacing, m")


def run(args) -> int:
    inputs = [args.bag] + ([args.probe] if args.probe else [])
    if os.path.isfile(args.bag) and not is_bag(args.bag):
        raise ValueError(
            f"{args.bag} is not a bag (a bag is a directory or an .mcap file): "
            "a table of fits is read by mows lab compare / report"
        )
    if args.csv:
        check_output(args.csv, inputs, args.force)
    probe = Probe.from_yaml(args.probe) if args.probe else PAPER_PROBE
    how = bag_fitting(args)
    with input_file(args.bag):
        fits = list(fit_bag(args.bag, probe, how))
        check_ringdowns(args.bag, [window for window, _ in fits], how)
    for window, fit in fits:
        print(
            f"cycle {window.cycle_id} repeat {window.repeat_index} θ0 {math.degrees(window.theta0_rad):7.2f}°: "
            f"{fit.report()}"
        )
    ok = [(w, f) for w, f in fits if f.ok]
    print(f"{len(ok)} of {len(fits)} ring-downs fitted")
    if args.csv and ok:
        with writing([args.csv], inputs, args.force) as outputs:
            notes = write_table(outputs.temporaries[0], ok, probe)
        print(f"{outputs.report()}: {len(ok)} rows")
        for note in notes:
            print(f"note: {note}")
    elif args.csv:
        print(f"mows fit: no ring-down fitted: {args.csv} not written", file=sys.stderr)
    return 0


def bag_fitting(args) -> BagFitting:
    """The bag arguments (:func:`add_fit_arguments`, ``--tuning``) as the core's settings of the same names."""
    return BagFitting(**{field.name: getattr(args, field.name) for field in dataclasses.fields(BagFitting)})


def check_ringdowns(path, windows, how: BagFitting) -> None:
    """ValueError when the bag holds no ring-down to fit, or ``--coil-off-skip-s`` skips all of each."""
    if not windows:
        raise ValueError(
            f"{path} holds no ring-down: no RINGDOWN phase on {how.excitation_topic} with samples on "
            f"{how.raw_topic}{'' if how.tuning else ' (tuning ones skipped: --tuning)'}"
        )
    longest = max(window.duration_s for window in windows)
    if how.coil_off_skip_s >= longest:
        raise ValueError(
            f"--coil-off-skip-s {how.coil_off_skip_s:g} s skips the whole of every ring-down (longest {longest:g} s)"
        )


def write_table(path, fits, probe: Probe) -> list[str]:
    """The OK fits as a model-lab table; returns notes of how the start swings were found.

    Every ring-down starts at the housing stop, so its swing is stop − |θs|
    (:func:`mows.physics.ringdown_average.start_swing_rad`). θs comes from the first-principles
    decomposition of all the fits as one sweep in one static field
    (:meth:`mows.sweep.record.SweepRecord.start_amplitudes_rad`) where that describes them
    (χ²/dof ≤ MAX_SWEEP_CHI2_DOF), else from each fit's own rest offset
    (:meth:`~mows.sweep.record.SweepRecord.fitted_start_amplitudes_rad`); the stop is pooled
    over the fits that determined θmax, else the probe's. The table is marked as the project's
    own (:func:`mows.lab.data.table.tool_table`)."""
    record = SweepRecord(
        [
            SweepPoint.from_fit(fit, fit.frequency_hz - probe.f00_hz, fit.frequency_std_hz, window.start_ns / NS_PER_S)
            for window, fit in fits
        ]
    )
    decomposition = record.decompose(probe, probe.f00_hz)
    if decomposition.ok and decomposition.chi2_dof <= MAX_SWEEP_CHI2_DOF:
        start = record.start_amplitudes_rad(decomposition, probe)
        notes = [f"start swings: the stop less the rest angle in the sweep's field ({decomposition.report()})"]
    else:
        start, notes = record.fitted_start_amplitudes_rad(probe.theta_stop_rad)
    tool_table(record.table_columns(start), str(path)).to_csv(path)
    return notes
