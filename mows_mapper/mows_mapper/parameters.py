"""The mapper's parameter table and the sweep settings it gives the core."""

import dataclasses

from mows.estimate.probe_set import own_probe_entry
from mows.estimate.settings import node_probes
from mows.physics.probe import Probe
from mows.sweep.events import REPEATS_PER_ANGLE_RANGE, SweepSettings
from mows.sweep.shift_model import MODELS
from mows_ros import operator
from mows_ros.params import ParamSpec
from mows_ros.probe import PROBE_FILE, PROBES


def reference_problem(name: str) -> str | None:
    """Why ``reference_scenario`` cannot serve as the lab's reference, or None."""
    try:
        if name:
            from mows.lab import reference_at  # only then: the lab's import is a second of CPU

            reference_at(name)
    except (OSError, ValueError, KeyError, TypeError) as error:
        return f"reference_scenario={name!r}: {error}"
    return None


PARAMETERS = (
    ParamSpec("repeats_per_angle", 5, "ring-downs per orientation when the goal says 0", range=REPEATS_PER_ANGLE_RANGE),
    ParamSpec("angle_step_deg", 30.0, "orientation step when the goal lists no angles, deg", range=(1.0, 180.0)),
    ParamSpec("model", "first_principles", "decomposition model when the goal names none", choices=MODELS),
    ParamSpec("f00_free", False, "fit the zero-field frequency in the decomposition (Gs is then undetermined)"),
    PROBE_FILE,
    # Read-only: /mows/sweep keeps one decomposition per probe for late subscribers.
    dataclasses.replace(PROBES, read_only=True),
    ParamSpec("cycle_timeout_s", 300.0, "longest wait for the driver's cycle, s", range=(1.0, 3600.0)),
    ParamSpec("fit_timeout_s", 10.0, "longest wait for the fits of a finished cycle, s", range=(0.1, 600.0)),
    ParamSpec(
        "reference_scenario",
        "",
        "scenario whose field at the probe is the lab's reference (shipped name or YAML); empty: no model report",
        check=reference_problem,
    ),
    ParamSpec("lab_auto", True, "let the lab add effects while the evidence is strong"),
    ParamSpec("frame_id", "mows_rotation_plane", "frame of the sweep: x = e1, y = e2 of the rotation plane"),
    ParamSpec(
        "repeat_s", 0.82, "adaptive sweeps: device time of one ring-down with its kick and gap, s", range=(0.01, 60.0)
    ),
    ParamSpec("turn_s", 0.5, "adaptive sweeps: device time to turn the probe and let it settle, s", range=(0.0, 60.0)),
    *operator.PARAMETERS,
    # The workspace map: the arm (CRTK topics <arm>/measured_cp, <arm>/move_cp) and the workspace.
    ParamSpec("arm", "arm", "namespace of the arm's CRTK topics (measured_cp, move_cp), e.g. PSM1"),
    ParamSpec(
        "turn_with",
        "stage",
        "workspace map: what turns the probe through a sweep's orientations: the stage, or the arm's last joint",
        choices=("stage", "arm"),
    ),
    ParamSpec("arm_frame", "arm_base", "the arm's base frame: measured_cp's frame_id, the map's frame"),
    ParamSpec("workspace_x_m", 0.3, "workspace map: centre's x in the arm's base frame when the goal gives none, m"),
    ParamSpec("workspace_y_m", 0.0, "workspace map: centre's y in the arm's base frame when the goal gives none, m"),
    ParamSpec("workspace_z_m", 0.0, "workspace map: centre's z in the arm's base frame when the goal gives none, m"),
    ParamSpec("workspace_radius_m", 0.025, "workspace map: radius when the goal gives none, m", range=(1e-3, 2.0)),
    ParamSpec("workspace_sweeps", 15, "workspace map: sweeps when the goal says 0", range=(3, 1000)),
    ParamSpec("reach_min_radius_m", 0.1, "the arm's reach: nearest to its base frame's origin, m", range=(0.0, 10.0)),
    ParamSpec(
        "reach_max_radius_m", 0.6, "the arm's reach: farthest from its base frame's origin, m", range=(0.0, 10.0)
    ),
    ParamSpec("arm_position_std_m", 1e-4, "the arm's stated position accuracy per component, m", range=(1e-9, 0.1)),
    ParamSpec("arm_angle_std_deg", 0.01, "the arm's stated rotation accuracy per component, deg", range=(1e-7, 10.0)),
    ParamSpec(
        "arm_tolerance_m",
        1e-4,
        "measured_cp this near the goal and its last report: arrived and still, m",
        range=(1e-7, 0.01),
    ),
    ParamSpec("arm_tolerance_deg", 0.05, "measured_cp this near in angle: arrived and still, deg", range=(1e-6, 5.0)),
    ParamSpec("pose_max_age_s", 0.5, "a measured_cp older than this cannot stand for a sweep, s", range=(0.001, 60.0)),
    ParamSpec("move_timeout_s", 60.0, "longest wait for the arm to report a pose asked for, s", range=(0.1, 3600.0)),
)


def sweep_settings(values: dict, probe: Probe) -> SweepSettings:
    """The settings of the next sweep; ``probe`` is ``probe_file``'s, for probes given by f00 alone."""
    return SweepSettings(
        values["repeats_per_angle"],
        values["angle_step_deg"],
        values["model"],
        values["f00_free"],
        values["repeat_s"],
        values["turn_s"],
        values["orientation"] == "manual",
        bool(values["probes"].strip()),
        probes=node_probes(values["probes"], own_probe_entry(probe)),
    )
