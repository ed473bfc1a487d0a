"""``mows map BAG``: the field map of a recorded session, made again offline as the mapper made it.

The bag is a recording of the graph (the driver's ``record_path``): its measurement cycles and
the estimator's fits recorded beside them go through the mapper's own sweep state machine
(:mod:`mows.sweep.replay`), one sweep per sweep the mapper published, with the cycles it names
(cycles after the last form one more; cycles before or between them, another client's or a
cancelled sweep's, are left out and counted). ``--refit`` fits the ring-downs again from the raw
stream, as ``mows fit`` does, with the same options, instead of taking the recorded fits. What
the bag does not hold are the mapper's parameters: ``--probe`` (``probe_file``), ``--probes``
(``probes``: the same YAML, docs/multi_probe.md), ``--model`` and ``--f00-free``. One line per
sweep, each probe's field and gradient in the mapper's words, or why that sweep cannot be made
again (too few orientations, say) beside the others; ``--json`` prints them as numbers (SI)
instead. A recording of a workspace map (the mapper's ``workspace_map``) is made again too, its
sweeps at their recorded poses (:mod:`mows.cli.map_workspace`). Exit status 2 only when no sweep
can be made again.
"""

import json
import os

import numpy as np

from mows.cli import map_workspace
from mows.cli.fit_bag import add_fit_arguments, bag_fitting, fit_settings
from mows.cli.inputs import input_file
from mows.estimate.probe_set import own_probe_entry
from mows.estimate.settings import node_probes
from mows.lab.data.readers import is_bag
from mows.lab.data.ringdowns import check_probes, fit_bag
from mows.physics.probe import PAPER_PROBE, Probe
from mows.sweep.events import SweepFit, SweepOutcome, SweepSettings
from mows.sweep.replay import RecordedCycle, read_session, replay_sweep
from mows.sweep.shift_model import MODELS


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
        probes = node_probes(args.probes, own_probe_entry(probe))
        settings = SweepSettings(
            model=args.model, f00_free=args.f00_free, probes=probes, named=bool(args.probes.strip())
        )
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
        if not settings.named:
            check_probes(args.bag, args.excitation_topic)
        sweeps = [(f"sweep {k}", cycles) for k, cycles in enumerate(session.sweeps(), 1)]
        if after := session.after_last():
            sweeps.append(("after the last recorded sweep", after))
        outcomes = [_replayed(cycles, fits, settings) for _, cycles in sweeps]
        if not any(outcome.maps or outcome.ok for outcome in outcomes):
            raise ValueError("; ".join(f"{name}: {outcome.message}" for (name, _), outcome in zip(sweeps, outcomes)))
        model, sweep_ids = map_workspace.recorded_map(args.bag)
        again = [(tuple(c.cycle_id for c in cycles), outcome) for (_, cycles), outcome in zip(sweeps, outcomes)]
        workspace = None if model is None else map_workspace.workspace_again(model, sweep_ids, again, probe)
    left_out = [c.cycle_id for c in session.left_out()]
    if args.json:
        made = [
            {"name": name, "cycle_ids": [c.cycle_id for c in cycles], **_numbers(outcome)}
            for (name, cycles), outcome in zip(sweeps, outcomes)
        ]
        numbers = {"sweeps": made, "left_out_cycle_ids": left_out}
        if workspace is not None:
            numbers["workspace"] = map_workspace.workspace_numbers(workspace)
        print(json.dumps(numbers))
        return 0
    for (name, cycles), outcome in zip(sweeps, outcomes):
        print(f"{name} ({len(cycles)} orientations): {outcome.message}")
    if left_out:
        print(f"{len(left_out)} cycles in no recorded sweep left out (cycle ids {', '.join(map(str, left_out))})")
    if workspace is not None:
        print(workspace.report())
    return 0


def _replayed(cycles: tuple[RecordedCycle, ...], fits, settings: SweepSettings) -> SweepOutcome:
    """The sweep of ``cycles`` made again; one the runner refuses (too few orientations) is a
    failed outcome with the reason, reported beside the others."""
    try:
        return replay_sweep(cycles, fits, settings)
    except ValueError as refused:
        return SweepOutcome(False, f"not made again: {refused}")


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
