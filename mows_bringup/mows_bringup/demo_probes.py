"""mows-demo on a scene of several probes (``--scenario three_probes``): one driver excites every
probe at once through the same coils, the estimator fits each ring-down window jointly into one
fit per probe, and the mapper decomposes each probe's sweep with its neighbours' fields in the
model and publishes the field map of all of them. Each probe's field and gradient are printed
against the scene's truth at its magnet.

The truth is what a rotation sweep determines (:mod:`mows.lab.data.truth`, docs/multi_probe.md).
The probes' constants are the scene's own: each real probe is calibrated first, one at a time,
as the single-probe demo does.
"""

import csv
import dataclasses
import pathlib
import time

import numpy as np
import yaml
from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.action import RotationSweep
from mows_msgs.msg import FieldMap, MagnetometerBlock, RingdownFit
from rclpy.action import ActionClient

from mows.lab.data.truth import Component, Pulls, against_truth, in_plane, in_plane_std
from mows.physics.multitone import MAX_PROBES
from mows.records.files import writing
from mows.sim.scenario import load_scenario
from mows_bringup.graph import say
from mows_ros.qos import MAP_QOS, RESULT_QOS, STREAM_QOS

MAP_FILE = "demo_field_map.csv"  # each probe's components against the truth
PROBE_FILES = tuple(f"probe_{k}.yaml" for k in range(MAX_PROBES))
LABELS = ("Bx (µT)", "By (µT)", "Gxx (mT/m)", "Gxy (mT/m)", "Gyy (mT/m)")
SCALES = np.array([1e6, 1e6, 1e3, 1e3, 1e3])  # SI to the printed units


def has_probes(scenario: str) -> bool:
    """Whether ``scenario`` is a scene of several probes (this module's demo)."""
    return len(load_scenario(scenario).probes) > 1


def write_probe_files(scenario: str, directory: pathlib.Path, inputs) -> list[pathlib.Path]:
    """Each probe's constants file, ``probe_<id>.yaml``, the id being its index in the scene."""
    paths = []
    for k, scene_probe in enumerate(load_scenario(scenario).probes):
        path = directory / PROBE_FILES[k]
        scene_probe.probe.to_yaml(path, {"source": f"the constants of probe {k} of the scene {scenario}"}, inputs, True)
        paths.append(path)
    return paths


def probes_parameter(scenario: str, paths: list[pathlib.Path]) -> str:
    """The estimator's and the mapper's ``probes``: each probe's file and its magnet's place, in
    the scene's frame (the rotation plane's: every probe of a scene turns in the x–y plane)."""
    entries = {
        k: {"probe_file": str(path), "position_m": [float(x) for x in p.pose.magnet_position_m]}
        for k, (path, p) in enumerate(zip(paths, load_scenario(scenario).probes))
    }
    return yaml.safe_dump(entries, default_flow_style=True).strip()


def sensor_parameters(scenario: str) -> dict:
    """The estimator's fluxgate geometry for the scene's pair: both sensors on one line from the
    scene's origin (the place the probes' ``position_m`` are counted from), reading along one axis.
    ValueError for a pair the estimator's parameters cannot describe."""
    pair = load_scenario(scenario).sensors.pair
    near, far = pair.positions_m
    distance = float(np.linalg.norm(near))
    direction = near / distance
    spacing = float(np.linalg.norm(far - near))
    axis = pair.sensors[0].axis
    if not np.allclose((far - near) / spacing, direction) or not np.isclose(axis[2], 0.0):
        raise ValueError(f"the scene {scenario}'s fluxgates are not on one line from its origin reading in-plane")
    return {
        "sensor_distance_m": distance,
        "sensor_spacing_m": spacing,
        "sensor_direction": [float(x) for x in direction],
        "sensor_axis_a": float(axis[0]),
        "sensor_axis_b": float(axis[1]),
    }


def parameters(args, scene_path: str, probe_paths: list[pathlib.Path]) -> dict:
    """The graph's parameter sections for the multi-probe sweep."""
    probes = probes_parameter(scene_path, probe_paths)
    driver = {"scenario": scene_path, "repeats": args.repeats, "tuning_steps": 0, "gap_s": args.gap_s}
    estimator = {"probes": probes, "probe_file": str(probe_paths[0]), **sensor_parameters(scene_path)}
    mapper = {"probes": probes, "repeats_per_angle": args.repeats, "probe_file": str(probe_paths[0])}
    return {
        "/**/driver": {"ros__parameters": driver},
        "/**/estimator": {"ros__parameters": estimator},
        "/**/mapper": {"ros__parameters": mapper},
    }


def sweep_client(node, spin_until) -> ActionClient:
    """The mapper's sweep action once the graph is ready for a sweep: the action served, the
    driver's samples streaming and the estimator hearing them (its /diagnostics count blocks;
    discovery takes seconds on a loaded machine, and a ring-down that began before the
    estimator's first block is a gap to it)."""
    blocks: list[int] = []
    heard: list[int] = []
    node.create_subscription(MagnetometerBlock, "mows/raw", lambda b: blocks.append(b.sequence), STREAM_QOS)
    node.create_subscription(DiagnosticArray, "/diagnostics", lambda a: heard.extend(_blocks_heard(a)), 10)
    client = ActionClient(node, RotationSweep, "mapper/rotation_sweep")
    spin_until(client.server_is_ready, 120.0, "the mapper's sweep action")
    spin_until(lambda: blocks, 60.0, "the driver's sample stream")
    spin_until(lambda: any(heard), 120.0, "the estimator hearing the stream")
    return client


def _blocks_heard(array: DiagnosticArray) -> list[int]:
    """The blocks the estimator reports heard, if ``array`` holds its status."""
    return [
        int(kv.value) for s in array.status if s.name.endswith("/estimator") for kv in s.values if kv.key == "blocks"
    ]


def accepted(spin_until, client: ActionClient, goal, feedback=None):
    """The goal's handle once the mapper accepted it; None, said, when it refused the sweep."""
    sent = client.send_goal_async(goal, feedback_callback=feedback)
    spin_until(sent.done, 30.0, "the goal to be accepted")
    if not sent.result().accepted:
        say("the mapper refused the sweep")
        return None
    return sent.result()


def run_sweep(node, spin_until, args, scenario: str, table: pathlib.Path, inputs) -> bool:
    """Sweep the shared stage through ``--angles`` orientations, print the field map against the
    truth and write it to ``table`` (CSV)."""
    maps: list[FieldMap] = []
    heard: dict[str, float] = {}  # when the last fit and the map arrived (this host's monotonic clock)
    node.create_subscription(
        FieldMap, "mows/field_map", lambda m: (maps.append(m), heard.update(map=time.monotonic())), MAP_QOS
    )
    node.create_subscription(RingdownFit, "mows/ringdown", lambda f: heard.update(fit=time.monotonic()), RESULT_QOS)
    client = sweep_client(node, spin_until)
    angles = np.radians(np.arange(args.angles) * 360.0 / args.angles)
    count = len(load_scenario(scenario).probes)
    say(f"sweep of {count} probes at once: {args.angles} orientations of the shared stage × {args.repeats} ring-downs")
    goal = RotationSweep.Goal(theta0_rad=angles.tolist(), repeats_per_angle=args.repeats)
    if (handle := accepted(spin_until, client, goal)) is None:
        return False
    result = handle.get_result_async()
    spin_until(result.done, 120.0 + args.angles * args.repeats * 30.0, "the sweep")
    outcome = result.result().result
    if not outcome.success:
        say(f"sweep failed: {outcome.message}")
        return False
    spin_until(lambda: maps, 30.0, "the field map")
    say(f"the field map came {heard['map'] - heard['fit']:.1f} s after the last ring-down's fit")
    rows = map_against_truth(scenario, maps[-1])
    print_rows(scenario, maps[-1], rows)
    with writing([table], inputs, force=True) as outputs:
        with open(outputs.temporaries[0], "w", newline="") as file:
            writer = csv.DictWriter(file, fieldnames=[field.name for field in dataclasses.fields(Component)])
            writer.writeheader()
            writer.writerows(dataclasses.asdict(row) for row in rows)
    say(f"the map against the truth: {table}")
    return all(point.status == 0 for point in maps[-1].probes)


def map_against_truth(scenario: str, field_map: FieldMap) -> list[Component]:
    """Each decomposed probe's five components against the truth at its magnet."""
    scene = load_scenario(scenario)
    rows: list[Component] = []
    for point in field_map.probes:
        if point.status == 0:
            value = in_plane(point.field_t, point.gradient_t_per_m)
            sigma = in_plane_std(point.field_covariance_t2, point.gradient_covariance)
            rows += against_truth(scene, point.probe_id, value, sigma)
    return rows


def print_rows(scenario: str, field_map: FieldMap, rows: list[Component]) -> None:
    """Each probe of the map against the truth, and the pulls over all of them."""
    scene = load_scenario(scenario)
    for point in field_map.probes:
        f00_hz = scene.placed_probes()[point.probe_id].probe.f00_hz
        where = ", ".join(f"{x * 100:.1f}" for x in point.position_m)
        say("")
        say(f"probe {point.probe_id} (f00 {f00_hz:g} Hz) at ({where}) cm: {point.message or 'decomposed'}")
        own = [row for row in rows if row.probe_id == point.probe_id]
        if own:
            say(f"  {'':12s} {'measured':>22s} {'truth':>10s} {'pull':>7s}")
        for label, row, scale in zip(LABELS, own, SCALES):
            say(
                f"  {label:12s} {row.value * scale:13.3f} ± {row.sigma * scale:6.3f} "
                f"{row.truth * scale:10.3f} {row.pull:7.2f}"
            )
    if rows:
        say("")
        say(Pulls.of(rows).report())
