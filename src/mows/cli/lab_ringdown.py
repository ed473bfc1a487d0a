"""``mows lab ringdown BAG``: inside each recorded ring-down, where a constant-frequency fit fails
and which effect explains it (:mod:`mows.lab.chirp`; docs/model_lab.md, "Inside one ring-down").

Each RINGDOWN phase of the bag is cut out of the raw blocks and fitted as ``mows fit`` does; the
window is then fitted piece by piece. One block of text per ring-down (or ``--json``); with
``--probes`` (a bag of several probes sharing each window) one per ring-down and probe, the
probes fitted jointly (:func:`mows.lab.chirp.diagnose_segment`). A bag
that cannot be read, or holds no ring-down that can be diagnosed, ends with one line and exit
status 2; a ring-down that cannot be diagnosed (failed fit, θmax not determined, too short) is
said in its block.
"""

from __future__ import annotations

import dataclasses
import json
import math

from mows.cli.fit_bag import bag_fitting, fit_settings
from mows.cli.inputs import InputError, input_file
from mows.lab.chirp import ChirpError, diagnose_segment
from mows.lab.data.ringdowns import recorded_ringdowns
from mows.physics.probe import PAPER_PROBE, Probe


def run_ringdown(args) -> int:
    how = bag_fitting(args)
    how = dataclasses.replace(how, parameters=dataclasses.replace(how.parameters, f00_hz=args.f00_hz or 0.0))
    probe = Probe.from_yaml(args.probe) if args.probe else PAPER_PROBE
    settings = fit_settings(how, probe)
    results: list[tuple] = []
    with input_file(args.bag):
        for segment in recorded_ringdowns(args.bag, settings, how):
            window = segment.window
            if args.cycle is not None and window.cycle_id != args.cycle:
                continue
            for probe_id, found in diagnose_segment(segment, settings, args.piece_periods):
                if isinstance(found, ChirpError):
                    results.append((window, probe_id, None, str(found)))
                else:
                    results.append((window, probe_id, found, ""))
    if not any(diagnosis for _, _, diagnosis, _ in results):
        what = f"cycle {args.cycle}" if args.cycle is not None else "any recorded ring-down"
        reasons = "; ".join(sorted({reason for *_, reason in results})) or "no RINGDOWN phase with its raw samples"
        raise InputError(f"{args.bag}: cannot diagnose {what}: {reasons}")
    if args.json:
        print(json.dumps([_as_dict(*result) for result in results], indent=2, default=float))
    else:
        print("\n\n".join(_text(*result) for result in results))
    return 0


def _heading(window, probe_id) -> str:
    """The window and the probe at its own θ0 (as announced, else the window's)."""
    theta0 = dict(zip(window.probe_ids, window.probe_theta0_rad)).get(probe_id, window.theta0_rad)
    return f"cycle {window.cycle_id} repeat {window.repeat_index} probe {probe_id} θ0 {math.degrees(theta0):.2f}°"


def _text(window, probe_id, diagnosis, reason) -> str:
    if diagnosis is None:
        return f"{_heading(window, probe_id)}: not diagnosed: {reason}"
    fit = diagnosis.fit
    lines = [
        f"{_heading(window, probe_id)}: constant-frequency fit: {fit.report()}",
        f"  field along the axis from this frequency (Eq. 6, finite amplitude removed): "
        f"{diagnosis.field_along_axis_t * 1e6:.4g} µT",
        "  piece  t (ms)   A (deg)   f − f_fit (mHz)        predicted (mHz)   δ (1/s)",
    ]
    for i, piece in enumerate(diagnosis.pieces):
        lines.append(
            f"  {i:5d}  {piece.t_s * 1e3:6.1f}   {math.degrees(piece.amplitude_rad):7.2f}   "
            f"{(piece.frequency_hz - fit.frequency_hz) * 1e3:+8.3f} ± {piece.frequency_std_hz * 1e3:6.3f}   "
            f"{(piece.predicted_hz - fit.frequency_hz) * 1e3:+8.3f}          {piece.damping_per_s:.3f}"
        )
    lines.append(
        f"  constant frequency over the pieces: χ²/dof = {diagnosis.constant_chi2_dof:.3g} "
        f"(p = {diagnosis.constant_p_value:.2g})"
    )
    lines.append(f"  verdict: {diagnosis.verdict}: {diagnosis.explanation}")
    return "\n".join(lines)


def _as_dict(window, probe_id, diagnosis, reason) -> dict:
    head = {
        "cycle_id": window.cycle_id,
        "repeat_index": window.repeat_index,
        "theta0_rad": window.theta0_rad,
        "probe_id": probe_id,
    }
    if diagnosis is None:
        return head | {"verdict": None, "reason": reason}
    found = {k: v for k, v in dataclasses.asdict(diagnosis).items() if k not in ("fit", "pieces")}
    return head | found | {"pieces": [dataclasses.asdict(p) for p in diagnosis.pieces]}
