"""Reading scenario YAML: ``extends:`` merging and the section builders.

A scenario's mapping is deep-merged over the one it ``extends:`` (a shipped name or a YAML path,
itself possibly extending another). Each section is built by a function whose signature is
the section's YAML keys (checked by :func:`mows.physics.schema.check_keys`), and the inverse
for the sections written back to YAML. :mod:`mows.sim.scenario` assembles the sections. A
refusal names its key path in the scenario (``probes[1].pose.magnet_position_m = …``,
:func:`mows.physics.schema.at`).
"""

from __future__ import annotations

import inspect
import math
import pathlib
from typing import Any

import numpy as np

from mows.physics import ranges
from mows.physics.field import source_from_dict
from mows.physics.fluxgate import FL1_RANGE_T, FL1_RESOLUTION_T, Fluxgate, FluxgatePair, NoiseModel
from mows.physics.multitone import MAX_PROBES
from mows.physics.pose import STANDARD_GRAVITY_M_PER_S2, Pose
from mows.physics.probe import PAPER_PROBE, Probe
from mows.physics.schema import at, check_keys, finite_number, load_yaml, refused, vector3
from mows.sim.sections import Environment, Excitation, SceneProbe, Sensors, floats

SCENARIO_DIR = pathlib.Path(__file__).with_name("scenarios")
BASE_SCENARIO = "base"  # what the shipped scenes share; not a scene of its own
PAPER_PROBE_NAME = "paper"


def shipped_scenarios() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml") if p.stem != BASE_SCENARIO)


# --- extends: a scenario as its base's mapping with overrides ---------------------------
def with_bases(data, base_dir, chain: tuple = ()) -> dict:
    """``data`` deep-merged over the scenario it ``extends`` (itself merged over its base …);
    its probe file path made relative to ``base_dir`` first. ``chain``: the files on the way."""
    if not isinstance(data, dict):
        raise ValueError(f"a scenario must be a mapping of sections, got {type(data).__name__}")
    data = dict(data)
    if data.get("probe") is not None and data.get("probes") is not None:
        raise ValueError("the scenario gives both probe: (the older shape of one probe) and probes: give one of them")
    data["probe"] = _relative_probe_file(data.get("probe"), base_dir)
    if isinstance(data.get("probes"), list):
        data["probes"] = [
            {**entry, "probe": _relative_probe_file(entry["probe"], base_dir)}
            if isinstance(entry, dict) and "probe" in entry
            else entry
            for entry in data["probes"]
        ]
    if data["probe"] is None:
        del data["probe"]
    if "extends" not in data:
        return data
    path = _base_path(data.pop("extends"), base_dir)
    if path in chain:
        raise ValueError("extends forms a cycle: " + " → ".join(p.name for p in (*chain, path)))
    base = load_yaml(path, "scenario", lambda given: with_bases(given, path.parent, (*chain, path)))
    return _deep_merge(base, data)


def _relative_probe_file(value, base_dir):
    """A probe file path made relative to ``base_dir``; any other probe value as it is."""
    if isinstance(value, str) and value != PAPER_PROBE_NAME:
        return str(pathlib.Path(base_dir or ".") / value)
    return value


def _base_path(name, base_dir) -> pathlib.Path:
    """The file of ``extends: name``: a YAML path (relative to ``base_dir``) or a shipped name."""
    if not isinstance(name, str):
        raise refused("extends", name, "must be a scenario name or a YAML file path")
    is_file = pathlib.Path(name).suffix in (".yaml", ".yml")
    path = pathlib.Path(base_dir or ".") / name if is_file else SCENARIO_DIR / f"{name}.yaml"
    if not path.is_file():
        raise refused(
            "extends",
            name,
            f"is neither a YAML file (looked for {path}) nor one of the shipped scenarios "
            f"{[BASE_SCENARIO, *shipped_scenarios()]}",
        )
    return path.resolve()


def _deep_merge(base: dict, override: dict) -> dict:
    """``override`` over ``base``: mappings merge key by key, anything else (lists too) replaces."""
    merged = dict(base)
    for key, value in override.items():
        both_maps = isinstance(value, dict) and isinstance(base.get(key), dict)
        merged[key] = _deep_merge(base[key], value) if both_maps else value
    return merged


# --- section builders: their signatures are the YAML keys --------------------------------
def require_explicit_geometry(pose: Pose, setup, sensors) -> None:
    """The coil presets and the default sensors lie in the global x–y plane (the paper's
    bench); a rotation plane other than x–y must say where its coils and sensors are."""
    if (pose.plane_e1, pose.plane_e2) == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
        return
    defaults = [
        what
        for what, default in (
            ("setup (a coil preset)", isinstance(setup, dict) and "preset" in setup),
            ("sensors (default positions)", not isinstance(sensors, dict) or "positions_m" not in sensors),
        )
        if default
    ]
    if defaults:
        raise ValueError(
            f"scenario: the rotation plane is not x–y (plane_e1 = {pose.plane_e1}, plane_e2 = "
            f"{pose.plane_e2}) but {' and '.join(defaults)} lie in x–y: give the coils "
            f"(setup: coils …) and the sensors (sensors: positions_m, axis) for this plane"
        )


def section(name: str | int, data, builder):
    """``builder(**data)`` after checking the keys against its signature; {} if absent. A
    refusal inside is at ``name`` (:func:`mows.physics.schema.at`)."""
    with at(name):
        data = {} if data is None else data
        if not isinstance(data, dict):
            raise refused("", data, "must be a mapping")
        check_keys("", data, builder)
        return builder(**data)


def probe_from(value) -> Probe:
    """The ``probe`` section: ``paper``, a probe YAML file or an inline mapping of constants."""
    with at("probe"):
        if isinstance(value, dict):
            return Probe.from_dict(value)
        if value == PAPER_PROBE_NAME:
            return PAPER_PROBE
        if isinstance(value, str):
            path = pathlib.Path(value)
            if not path.is_file():
                raise refused("", value, f"is neither {PAPER_PROBE_NAME!r} nor a probe file (looked for {path})")
            return Probe.from_yaml(path)
        raise refused("", value, f"must be {PAPER_PROBE_NAME!r}, a file path or a mapping")


def probes_from(entries) -> tuple[SceneProbe, ...]:
    """The ``probes:`` list of a scene's probes (one or several): each entry a mapping of ``probe``
    (as the ``probe`` section), ``pose`` (as the ``pose`` section) and ``stage`` (own | shared)."""
    if not isinstance(entries, list) or not 1 <= len(entries) <= MAX_PROBES:
        raise refused("probes", entries, f"must be a list of 1 to {MAX_PROBES} probes")
    with at("probes"):
        return tuple(section(k, entry, _scene_probe) for k, entry in enumerate(entries))


def _scene_probe(probe=PAPER_PROBE_NAME, pose=None, stage="own") -> SceneProbe:
    return SceneProbe(probe_from(probe), section("pose", pose, pose_from), stage)


def environment_from(
    sources=(), temperature_k=Environment.temperature_k, temperature_rate_k_per_s=Environment.temperature_rate_k_per_s
):
    if not isinstance(sources, (list, tuple)):
        raise refused("sources", sources, "must be a list of field sources")
    with at("sources"):
        built = []
        for k, source in enumerate(sources):
            with at(k):
                built.append(source_from_dict(source))
    return Environment(
        tuple(built),
        finite_number("temperature_k", temperature_k),
        finite_number("temperature_rate_k_per_s", temperature_rate_k_per_s),
    )


def pose_from(
    magnet_position_m=(0.0, 0.0, 0.0),
    theta0_deg=0.0,
    plane_e1=(1.0, 0.0, 0.0),
    plane_e2=(0.0, 1.0, 0.0),
    gravity_m_per_s2=None,
    tilt_deg=None,
    tilt_axis_deg=0.0,
) -> Pose:
    place: dict[str, Any] = {
        "magnet_position_m": tuple(floats(vector3("magnet_position_m", magnet_position_m))),
        "theta0_rad": math.radians(finite_number("theta0_deg", theta0_deg)),
    }
    plane: dict[str, Any] = {
        "plane_e1": tuple(floats(vector3("plane_e1", plane_e1))),
        "plane_e2": tuple(floats(vector3("plane_e2", plane_e2))),
    }
    if tilt_deg is None:
        gravity = (0.0, 0.0, -STANDARD_GRAVITY_M_PER_S2) if gravity_m_per_s2 is None else gravity_m_per_s2
        return Pose(gravity_m_per_s2=tuple(floats(vector3("gravity_m_per_s2", gravity))), **place, **plane)
    if gravity_m_per_s2 is not None or plane != {"plane_e1": (1.0, 0.0, 0.0), "plane_e2": (0.0, 1.0, 0.0)}:
        raise ValueError(
            "tilt_deg describes the x–y plane tilted under gravity; "
            "give either tilt_deg (and tilt_axis_deg) or gravity_m_per_s2 with plane_e1/plane_e2"
        )
    tilt = finite_number("tilt_deg", tilt_deg)
    if not -90.0 <= tilt <= 90.0:
        raise refused("tilt_deg", tilt, "must be in [-90, 90]")
    return Pose.tilted(math.radians(tilt), math.radians(finite_number("tilt_axis_deg", tilt_axis_deg)), **place)


def pose_to_dict(pose: Pose) -> dict:
    return {
        "magnet_position_m": floats(pose.magnet_position_m),
        "theta0_deg": math.degrees(pose.theta0_rad),
        "plane_e1": floats(pose.plane_e1),
        "plane_e2": floats(pose.plane_e2),
        "gravity_m_per_s2": floats(pose.gravity_m_per_s2),
    }


def _check_places(positions: np.ndarray, magnet_m: np.ndarray) -> None:
    """Two fluxgates are two places, each away from the magnet: a sensor is millimetres across."""
    lowest = ranges.RANGES["sensor_length_m"].possible[0]
    apart = float(np.linalg.norm(positions[1] - positions[0]))
    if apart < lowest:
        raise refused(
            "positions_m",
            positions.tolist(),
            f"puts both fluxgates at one spot ({apart:g} m apart): "
            "the difference channel would read nothing; give their two places",
        )
    for k, position in enumerate(positions):
        distance = float(np.linalg.norm(position - magnet_m))
        if distance < lowest:
            raise refused(
                f"positions_m[{k}]",
                position.tolist(),
                f"is {distance:g} m from the magnet: "
                "a fluxgate cannot sit at the magnet; give its place on the line from the probe",
            )


def sensors_from(
    pose: Pose,
    positions_m=None,
    axis=(0.0, 1.0, 0.0),
    range_t=FL1_RANGE_T,
    resolution_t=FL1_RESOLUTION_T,
    null_offsets=True,
) -> Sensors:
    """Two parallel sensors; by default at the paper's places relative to the magnet's rest position."""
    if positions_m is None:
        positions = FluxgatePair.paper(pose.magnet_position_m).positions_m
    else:
        listed = isinstance(positions_m, (list, tuple, np.ndarray))
        positions = np.array([vector3("positions_m", p) for p in positions_m] if listed else [])
        if positions.shape != (2, 3):
            raise refused("positions_m", positions_m, "must be two 3-vectors")
        _check_places(positions, np.asarray(pose.magnet_position_m, float))
    if not isinstance(null_offsets, bool):
        raise refused("null_offsets", null_offsets, "must be true or false")
    sensors = [
        Fluxgate(p, axis, finite_number("range_t", range_t), finite_number("resolution_t", resolution_t))
        for p in positions
    ]
    return Sensors(FluxgatePair(tuple(sensors)), null_offsets)


def sensors_to_dict(sensors: Sensors) -> dict:
    near = sensors.pair.sensors[0]
    return {
        "positions_m": sensors.pair.positions_m.tolist(),
        "axis": floats(near.axis),
        "range_t": float(near.range_t),
        "resolution_t": float(near.resolution_t),
        "null_offsets": sensors.null_offsets,
    }


def numbers_into(cls):
    """A builder that converts every value to float before calling ``cls`` (same keys)."""

    def build(**values):
        return cls(**{k: finite_number(k, v) for k, v in values.items()})

    build.__signature__ = inspect.signature(cls)
    return build


noise_from = numbers_into(NoiseModel)


def excitation_from(
    amplitude_a=Excitation.amplitude_a,
    frequency_hz=None,
    excite_s=Excitation.excite_s,
    ringdown_s=Excitation.ringdown_s,
    gap_s=Excitation.gap_s,
) -> Excitation:
    values = {
        k: finite_number(k, v)
        for k, v in dict(amplitude_a=amplitude_a, excite_s=excite_s, ringdown_s=ringdown_s, gap_s=gap_s).items()
    }
    frequency = None if frequency_hz is None else finite_number("frequency_hz", frequency_hz)
    return Excitation(frequency_hz=frequency, **values)
