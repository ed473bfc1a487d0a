"""``mows map BAG``'s workspace map: a recording of the mapper's ``workspace_map`` made again.

The recorded map (``/mows/workspace_model``, the last one) names its sweeps (``sweep_ids``),
the pose the arm reported for each, the workspace and the arm's accuracy; the recorded
``/mows/sweep`` messages name each sweep's measurement cycles. Each sweep the command made
again from its cycles (:mod:`mows.cli.map_bag`) enters the map at its recorded pose, fitted by
the mapper's own :func:`mows.workspace.mapping.workspace_map`: one path, live and offline.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from mows.device.recording.bags import read_bag
from mows.physics.probe import Probe
from mows.sweep.events import SweepOutcome
from mows.workspace.arm import StampedPose
from mows.workspace.mapping import MapSettings, WorkspaceMap, workspace_map
from mows.workspace.poses import PoseError

MODEL_TOPIC, SWEEP_TOPIC = "/mows/workspace_model", "/mows/sweep"


def recorded_map(bag) -> tuple[object | None, dict[tuple[int, ...], int]]:
    """The bag's last recorded workspace map (None without one) and each recorded sweep's id by
    its cycles."""
    model, sweeps = None, {}
    for item in read_bag(bag, topics=(MODEL_TOPIC, SWEEP_TOPIC)):
        if item.topic == MODEL_TOPIC:
            model = item.message
        else:
            sweeps[tuple(int(c) for c in item.message.cycle_ids)] = int(item.message.sweep_id)
    return model, sweeps


def workspace_again(
    model, sweep_ids: dict[tuple[int, ...], int], made: Sequence[tuple[tuple[int, ...], SweepOutcome]], probe: Probe
) -> WorkspaceMap:
    """The map of the recorded ``model`` from the sweeps ``made`` again (each with its cycle
    ids); ValueError when one of its sweeps was not made again."""
    outcomes = {sweep_ids.get(cycles): outcome for cycles, outcome in made}
    sweeps = []
    for sweep_id, pose in zip(model.sweep_ids, model.poses):
        outcome = outcomes.get(int(sweep_id))
        if outcome is None or not outcome.ok or outcome.map is None:
            why = "not in the recording" if outcome is None else outcome.message
            raise ValueError(f"the workspace map's sweep {sweep_id} cannot be made again: {why}")
        sweeps.append((outcome.map.decomposition, StampedPose.of(pose)))
    settings = MapSettings(
        tuple(float(c) for c in model.centre_m),
        float(model.radius_m),
        PoseError(float(model.pose_std_m), float(model.pose_std_rad)),
        frame_id=model.header.frame_id,
    )
    return workspace_map(sweeps, probe, settings)


def workspace_numbers(the_map: WorkspaceMap) -> dict:
    model = the_map.model
    return {
        "degree": model.basis.max_degree,
        "sweeps": len(the_map.poses),
        "coefficients_t": model.coefficients.tolist(),
        "coefficient_std_t": np.sqrt(np.diag(model.covariance)).tolist(),
        "chi2": model.chi2,
        "dof": model.dof,
    }
