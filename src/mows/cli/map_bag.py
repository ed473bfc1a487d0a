"""``mows map BAG``: the field map of a recorded session, made again offline as the mapper made it.

The bag is a recording of the graph (the driver's ``record_path``): its measurement cycles and
the estimator's fits recorded beside them go through the mapper's own sweep state machine
(:mod:`mows.sweep.replay`), one sweep per sweep the mapper published (cycles after the last form
one more). ``--refit`` fits the ring-downs again from the raw stream, as ``mows fit`` does, with
the same options, instead of taking the recorded fits. What the bag does not hold are the
mapper's parameters: ``--probe`` (``probe_file``), ``--probes`` (``probes``: the same YAML,
docs/multi_probe.md), ``--model`` and ``--f00-free``. One line per sweep, each probe's field and
gradient in the mapper's words; ``--json`` prints them as numbers (SI) instead.
"""

import json
import os

import numpy as np

from mows.cli.fit_bag import add_fit_arguments, bag_fitting, fit_settings
from mows.cli.inputs import input_file
from mows.estimate.settings import probe_set
from mows.lab.data.readers import is_bag
from mows.lab.data.ringdowns import check_probes, fit_bag
from mows.physics.probe import PAPER_PROBE, Probe
from mows.sweep.decompose import MODELS
from mows.sweep.replay import read_session, replay_sweep
from mows.sweep.runner import SweepFit, SweepOutcome, SweepSettings


def add_arguments(parser) -> None:
    parser.add_argument("bag", help="a rosbag2 directory (or .mcap) the driver recorded with the graph running")
    parser.add_argument("--probe", help="probe constants YAML, the mapper's probe_file (default: the paper's probe)")
    parser.add_argument(
        "--probes",
        default="",
        metavar="SPEC",
        help="the probes of each sweep, the mapper's (and the estimator's) probes parameter, YAML "
        "{ID: F00_HZ | PROBE_FILE | {f00_hz, f00_std_hz, probe_file, position_m}, ...} (docs/multi_probe.md)",
    )
    parser.add_argument("--model", choices=MODELS, default=SweepSettings.model, help="the decomposition's model")
    parser.add_argument("--f00-free", action="store_true", help="fit f00 with the field (the mapper's f00_free)")
    parser.add_argument("--refit", action="store_true", help="fit the ring-downs again from the raw stream")
    parser.add_argument("--json", action="store_true", help="each sweep's maps as JSON numbers (SI)")
    add_fit_arguments(parser)
    parser.set_defaults(tuning=False)


def run(args) -> int:
    if os.path.isfile(args.bag) and not is_bag(args.bag):
        raise ValueError(f"{args.bag} is not a bag (a bag is a directory or an .mcap file)")
    probe = Probe.from_yaml(args.probe) if args.probe else PAPER_PROBE
    try:
        settings = SweepSettings(model=args.model, f00_free=args.f00_free, probes=probe_set(args.probes, probe))
    except ValueError as error:
        raise ValueError(f"--probes: {error}") from None
    with input_file(args.bag):
        session = read_session(args.bag)
        fits = session.fits
        if args.refit:
            how = bag_fitting(args)
            fits = tuple(SweepFit.from_estimated(e) for e in fit_bag(args.bag, fit_settings(how, probe), how))
        if not fits:
            raise ValueError("no ring-down fit recorded (the estimator was not running?): --refit fits the raw stream")
        if not settings.probes:
            check_probes(args.bag, args.excitation_topic)
        sweeps = session.sweeps()
        outcomes = [replay_sweep(cycles, fits, settings, probe) for cycles in sweeps]
    if args.json:
        print(json.dumps({"sweeps": [_numbers(outcome) for outcome in outcomes]}))
        return 0
    for k, (cycles, outcome) in enumerate(zip(sweeps, outcomes), 1):
        print(f"sweep {k} ({len(cycles)} orientations): {outcome.message}")
    return 0


def _numbers(outcome: SweepOutcome) -> dict:
    """A sweep's outcome, each probe's map as plain numbers (NaN as null)."""

    def plain(values) -> list:
        return [None if not np.isfinite(x) else float(x) for x in np.ravel(values)]

    maps = [
        {
            "probe_id": m.probe_id,
            "status": m.decomposition.status.name,
            "field_t": plain(m.decomposition.field_t),
            "field_std_t": plain(np.sqrt(np.diag(m.decomposition.field_covariance_t2))),
            "gradient_t_per_m": plain(m.decomposition.gradient_t_per_m),
            "gradient_std_t_per_m": plain(np.sqrt(np.diag(m.decomposition.gradient_covariance))),
            "chi2_dof": plain([m.decomposition.chi2_dof])[0],
            "points": len(m.record.points),
        }
        for m in outcome.maps
    ]
    return {"ok": outcome.ok, "message": outcome.message, "maps": maps}
