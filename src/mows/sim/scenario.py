"""Simulator scenarios: what is simulated, as dataclasses and as YAML (docs/scenario_format.md).

A scenario fixes the probe, the excitation coil setup, the static environment (field sources,
temperature), where the probe sits and how it is turned (:class:`mows.physics.pose.Pose`), the two
fluxgates, their noise, the default excitation, the housing stop and the integrator. Every
section has defaults; ``Scenario()`` is the paper's probe in the largest-spacing setup with no
environment field and no noise, and ``load_scenario()`` is the documented default scenario
(the paper's device in its largest-spacing setup, in the Earth's field).

YAML keys carry SI unit suffixes; degrees appear only in keys ending ``_deg``. Unknown keys,
missing required keys and out-of-range values raise ValueError naming the section and key.
Shipped scenarios live in ``src/mows/sim/scenarios/<name>.yaml`` and are loaded by name. A
scenario may ``extends:`` another (a shipped name or a YAML path): its mapping is deep-merged
over the base's, so the shipped scenes state only how they differ from ``base.yaml``.
"""
from __future__ import annotations

import dataclasses
import functools
import inspect
import math
import pathlib
from typing import Any

import numpy as np
import yaml

from mows.physics.coils import CoilSetup, largest_spacing, setup_from_dict
from mows.physics.field import FieldSource, SumSource, source_from_dict, source_to_dict
from mows.physics.fluxgate import DAQ_SAMPLE_RATE_HZ, FL1_RANGE_T, FL1_RESOLUTION_T, Fluxgate, FluxgatePair, NoiseModel
from mows.physics.pose import STANDARD_GRAVITY_M_PER_S2, Pose
from mows.physics.probe import PAPER_PROBE, Probe
from mows.physics.schema import check_keys, vector3
from mows.physics.supply import FieldSupply, supply_from_dict

SCENARIO_DIR = pathlib.Path(__file__).with_name("scenarios")
DEFAULT_SCENARIO = "paper_largest_spacing"
BASE_SCENARIO = "base"     # what the shipped scenes share; not a scene of its own
PAPER_PROBE_NAME = "paper"


# --- small helpers -------------------------------------------------------------------------
def _number(section: str, key: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"scenario section {section!r}: {key} = {value!r} must be a number")
    return float(value)


def _check(section, key, value, low, high, low_open=False):
    ok = math.isfinite(value) and (low < value if low_open else low <= value) and value <= high
    if not ok:
        bracket = "(" if low_open else "["
        raise ValueError(f"{section}: {key} = {value!r} is out of range {bracket}{low:g}, {high:g}]")


def _floats(vector) -> list:
    return [float(v) for v in vector]


# --- sections that have no dataclass elsewhere ------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class Environment:
    """The static surroundings: field sources (global frame) and the temperature.

    ``temperature_k`` at device time 0 drifts linearly at ``temperature_rate_k_per_s``; the
    probe's kM follows it (PHYSICS.md §5.6, :meth:`mows.physics.probe.Probe.spring_at`).
    """

    sources: tuple = ()
    temperature_k: float = PAPER_PROBE.reference_temperature_k
    temperature_rate_k_per_s: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "sources", tuple(self.sources))
        if not all(isinstance(s, FieldSource) for s in self.sources):
            raise ValueError(f"environment sources must be field sources, got {self.sources!r}")
        _check("environment", "temperature_k", self.temperature_k, 0.0, math.inf, low_open=True)
        _check("environment", "temperature_rate_k_per_s", self.temperature_rate_k_per_s, -1.0, 1.0)

    @property
    def source(self) -> FieldSource:
        """All sources superposed (the zero field when there are none)."""
        return SumSource(self.sources)

    def temperature_at(self, time_s):
        """T(t) = T0 + rate·t, K."""
        return self.temperature_k + self.temperature_rate_k_per_s * time_s


@dataclasses.dataclass(frozen=True, eq=False)
class Sensors:
    """The fluxgate pair; with ``null_offsets`` the device nulls the static environment field
    at each sensor when it starts, like the instruments' offset compensation."""

    pair: FluxgatePair = dataclasses.field(default_factory=FluxgatePair.paper)
    null_offsets: bool = True


@dataclasses.dataclass(frozen=True)
class Excitation:
    """Default excitation of one cycle.

    ``amplitude_a``: base current amplitude of the setup's current scheme (≤ the cap);
    ``frequency_hz``: drive frequency, None for the probe's expected frequency (the paper tunes
    it to the resonance); ``excite_s``, ``ringdown_s``: coil-on and recorded ring-down time;
    ``gap_s``: pause between repeats (paper: 10 s).
    """

    amplitude_a: float = 2.0
    frequency_hz: float | None = None
    excite_s: float = 0.5
    ringdown_s: float = 0.5
    gap_s: float = 10.0

    def __post_init__(self):
        _check("excitation", "amplitude_a", self.amplitude_a, 0.0, math.inf)
        if self.frequency_hz is not None:
            _check("excitation", "frequency_hz", self.frequency_hz, 0.0, math.inf, low_open=True)
        _check("excitation", "excite_s", self.excite_s, 0.0, 3600.0)
        _check("excitation", "ringdown_s", self.ringdown_s, 0.0, 3600.0, low_open=True)
        _check("excitation", "gap_s", self.gap_s, 0.0, 3600.0)


@dataclasses.dataclass(frozen=True)
class Housing:
    """The housing stop at ±θstop as a stiff spring–dashpot contact (see :mod:`mows.sim.kernel`).

    ``stiffness_ratio``: contact stiffness over kM; ``restitution``: coefficient of
    restitution of one impact (sets the contact damping).
    """

    stiffness_ratio: float = 1000.0
    restitution: float = 0.5

    def __post_init__(self):
        _check("housing", "stiffness_ratio", self.stiffness_ratio, 10.0, 1e5)
        _check("housing", "restitution", self.restitution, 0.0, 1.0, low_open=True)


@dataclasses.dataclass(frozen=True)
class Integrator:
    """RK4 steps per sample: ``substeps`` in free flight, ``contact_substeps`` near the stop."""

    substeps: int = 2
    contact_substeps: int = 16

    def __post_init__(self):
        for name in ("substeps", "contact_substeps"):
            value = getattr(self, name)
            if not (isinstance(value, (int, np.integer)) and 1 <= value <= 1000):
                raise ValueError(f"integrator: {name} = {value!r} must be an integer in [1, 1000]")


@dataclasses.dataclass(frozen=True, eq=False)
class Scenario:
    """Everything the simulator needs (module docstring); build variants with :meth:`replace`."""

    probe: Probe = PAPER_PROBE
    setup: CoilSetup = dataclasses.field(default_factory=largest_spacing)
    environment: Environment = Environment()
    pose: Pose = Pose()
    sensors: Sensors = dataclasses.field(default_factory=Sensors)
    noise: NoiseModel = NoiseModel()
    excitation: Excitation = Excitation()
    housing: Housing = Housing()
    integrator: Integrator = Integrator()
    sample_rate_hz: float = DAQ_SAMPLE_RATE_HZ
    seed: int = 1
    name: str = "custom"
    description: str = ""
    supply: FieldSupply | None = None   # the static-field supply the driver controls (calibration)

    def __post_init__(self):
        _check("scenario", "sample_rate_hz", self.sample_rate_hz, 0.0, 1e7, low_open=True)
        if not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise ValueError(f"scenario: seed = {self.seed!r} must be an integer ≥ 0")
        self.setup.cap.check(self.excitation.amplitude_a)

    def replace(self, **changes) -> Scenario:
        return dataclasses.replace(self, **changes)

    # --- YAML ---------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: dict, base_dir=None) -> Scenario:
        """Scenario from its YAML mapping; probe file paths and an ``extends:`` file path are
        relative to ``base_dir`` (in a base file: to that file's folder)."""
        data = _with_bases(data, base_dir)
        check_keys("scenario", data, _scenario_from_sections)
        return _scenario_from_sections(**data)

    def to_dict(self) -> dict:
        """The full YAML mapping (presets and the paper probe written out in full)."""
        return {
            "name": self.name, "description": self.description,
            "probe": self.probe.to_dict(), "setup": self.setup.to_dict(),
            "environment": {"sources": [source_to_dict(s) for s in self.environment.sources],
                            "temperature_k": float(self.environment.temperature_k),
                            "temperature_rate_k_per_s": float(self.environment.temperature_rate_k_per_s)},
            "pose": _pose_to_dict(self.pose),
            "sensors": _sensors_to_dict(self.sensors),
            "noise": {k: float(v) for k, v in dataclasses.asdict(self.noise).items()},
            "excitation": dataclasses.asdict(self.excitation),
            "housing": dataclasses.asdict(self.housing),
            "integrator": dataclasses.asdict(self.integrator),
            "sample_rate_hz": float(self.sample_rate_hz), "seed": int(self.seed),
            **({} if self.supply is None else {"supply": self.supply.to_dict()}),
        }

    @classmethod
    def from_yaml(cls, path) -> Scenario:
        path = pathlib.Path(path)
        data = yaml.safe_load(path.read_text())
        return cls.from_dict(data, base_dir=path.parent)

    def to_yaml(self, path) -> None:
        pathlib.Path(path).write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))


def load_scenario(name_or_path=DEFAULT_SCENARIO) -> Scenario:
    """A shipped scenario by name (``src/mows/sim/scenarios/<name>.yaml``) or a YAML file by path."""
    path = pathlib.Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        path = SCENARIO_DIR / f"{name_or_path}.yaml"
        if not path.is_file():
            raise ValueError(f"scenario {name_or_path!r} is neither a YAML file nor one of the shipped "
                             f"scenarios {shipped_scenarios()}")
    return Scenario.from_yaml(path)


def shipped_scenarios() -> list[str]:
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.yaml") if p.stem != BASE_SCENARIO)


# --- extends: a scenario as its base's mapping with overrides ---------------------------
def _with_bases(data, base_dir, chain: tuple = ()) -> dict:
    """``data`` deep-merged over the scenario it ``extends`` (itself merged over its base …);
    its probe file path made relative to ``base_dir`` first. ``chain``: the files on the way."""
    if not isinstance(data, dict):
        raise ValueError(f"a scenario must be a mapping of sections, got {type(data).__name__}")
    data = dict(data)
    if isinstance(data.get("probe"), str) and data["probe"] != PAPER_PROBE_NAME:
        data["probe"] = str(pathlib.Path(base_dir or ".") / data["probe"])
    if "extends" not in data:
        return data
    path = _base_path(data.pop("extends"), base_dir)
    if path in chain:
        raise ValueError("scenario: extends forms a cycle: " + " → ".join(p.name for p in (*chain, path)))
    base = _with_bases(yaml.safe_load(path.read_text()), path.parent, (*chain, path))
    return _deep_merge(base, data)


def _base_path(name, base_dir) -> pathlib.Path:
    """The file of ``extends: name``: a YAML path (relative to ``base_dir``) or a shipped name."""
    if not isinstance(name, str):
        raise ValueError(f"scenario: extends = {name!r} must be a scenario name or a YAML file path")
    is_file = pathlib.Path(name).suffix in (".yaml", ".yml")
    path = pathlib.Path(base_dir or ".") / name if is_file else SCENARIO_DIR / f"{name}.yaml"
    if not path.is_file():
        raise ValueError(f"scenario: extends = {name!r} is neither a YAML file (looked for {path}) nor one of "
                         f"the shipped scenarios {[BASE_SCENARIO, *shipped_scenarios()]}")
    return path.resolve()


def _deep_merge(base: dict, override: dict) -> dict:
    """``override`` over ``base``: mappings merge key by key, anything else (lists too) replaces."""
    merged = dict(base)
    for key, value in override.items():
        both_maps = isinstance(value, dict) and isinstance(base.get(key), dict)
        merged[key] = _deep_merge(base[key], value) if both_maps else value
    return merged


# --- section builders: their signatures are the YAML keys --------------------------------
def _scenario_from_sections(name="custom", description="", probe=PAPER_PROBE_NAME, setup=None, environment=None,
                   pose=None, sensors=None, noise=None, excitation=None, housing=None, integrator=None,
                   sample_rate_hz=Scenario.sample_rate_hz, seed=Scenario.seed, supply=None) -> Scenario:
    the_pose = _section("pose", pose, _pose)
    fs = _number("scenario", "sample_rate_hz", sample_rate_hz)
    setup = {"preset": "largest_spacing"} if setup is None else setup
    _require_explicit_geometry(the_pose, setup, sensors)
    if isinstance(setup, dict) and "preset" in setup:   # the preset's coils sit around the probe
        setup = {"probe_position_m": list(the_pose.magnet_position_m), **setup}
    return Scenario(
        probe=_probe(probe),
        setup=setup_from_dict(setup),
        environment=_section("environment", environment, _environment),
        pose=the_pose,
        sensors=_section("sensors", sensors, functools.partial(_sensors, the_pose)),
        noise=_section("noise", noise, _noise),
        excitation=_section("excitation", excitation, _excitation),
        housing=_section("housing", housing, _numbers_into(Housing)),
        integrator=_section("integrator", integrator, Integrator),
        sample_rate_hz=fs, seed=seed, name=str(name), description=str(description),
        supply=None if supply is None else supply_from_dict(supply))


def _require_explicit_geometry(pose: Pose, setup, sensors) -> None:
    """The coil presets and the default sensors lie in the global x–y plane (the paper's
    bench); a rotation plane other than x–y must say where its coils and sensors are."""
    if (pose.plane_e1, pose.plane_e2) == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0)):
        return
    defaults = [what for what, default in (("setup (a coil preset)", isinstance(setup, dict) and "preset" in setup),
                                           ("sensors (default positions)",
                                            not isinstance(sensors, dict) or "positions_m" not in sensors))
                if default]
    if defaults:
        raise ValueError(f"scenario: the rotation plane is not x–y (plane_e1 = {pose.plane_e1}, plane_e2 = "
                         f"{pose.plane_e2}) but {' and '.join(defaults)} lie in x–y: give the coils "
                         f"(setup: coils …) and the sensors (sensors: positions_m, axis) for this plane")


def _section(name, data, builder):
    """``builder(**data)`` after checking the keys against its signature; {} if absent."""
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise ValueError(f"scenario section {name!r} must be a mapping, got {data!r}")
    check_keys(f"scenario section {name!r}", data, builder)
    return builder(**data)


def _probe(value) -> Probe:
    """``paper``, a probe YAML file or an inline mapping of constants."""
    if isinstance(value, dict):
        return Probe.from_dict(value)
    if value == PAPER_PROBE_NAME:
        return PAPER_PROBE
    if isinstance(value, str):
        path = pathlib.Path(value)
        if not path.is_file():
            raise ValueError(f"scenario section 'probe': {value!r} is neither {PAPER_PROBE_NAME!r} nor a probe "
                             f"file (looked for {path})")
        return Probe.from_yaml(path)
    raise ValueError(f"scenario section 'probe' must be {PAPER_PROBE_NAME!r}, a file path or a mapping, got {value!r}")


def _environment(sources=(), temperature_k=Environment.temperature_k,
                 temperature_rate_k_per_s=Environment.temperature_rate_k_per_s):
    if not isinstance(sources, (list, tuple)):
        raise ValueError(f"scenario section 'environment': sources must be a list of field sources, got {sources!r}")
    return Environment(tuple(source_from_dict(s) for s in sources),
                       _number("environment", "temperature_k", temperature_k),
                       _number("environment", "temperature_rate_k_per_s", temperature_rate_k_per_s))


def _pose(magnet_position_m=(0.0, 0.0, 0.0), theta0_deg=0.0, plane_e1=(1.0, 0.0, 0.0), plane_e2=(0.0, 1.0, 0.0),
          gravity_m_per_s2=None, tilt_deg=None, tilt_axis_deg=0.0) -> Pose:
    place: dict[str, Any] = {"magnet_position_m": tuple(_floats(vector3("pose: magnet_position_m", magnet_position_m))),
             "theta0_rad": math.radians(_number("pose", "theta0_deg", theta0_deg))}
    plane: dict[str, Any] = {"plane_e1": tuple(_floats(vector3("pose: plane_e1", plane_e1))),
             "plane_e2": tuple(_floats(vector3("pose: plane_e2", plane_e2)))}
    if tilt_deg is None:
        gravity = (0.0, 0.0, -STANDARD_GRAVITY_M_PER_S2) if gravity_m_per_s2 is None else gravity_m_per_s2
        return Pose(gravity_m_per_s2=tuple(_floats(vector3("pose: gravity_m_per_s2", gravity))), **place, **plane)
    if gravity_m_per_s2 is not None or plane != {"plane_e1": (1.0, 0.0, 0.0), "plane_e2": (0.0, 1.0, 0.0)}:
        raise ValueError("scenario section 'pose': tilt_deg describes the x–y plane tilted under gravity; "
                         "give either tilt_deg (and tilt_axis_deg) or gravity_m_per_s2 with plane_e1/plane_e2")
    tilt = _number("pose", "tilt_deg", tilt_deg)
    if not -90.0 <= tilt <= 90.0:
        raise ValueError(f"scenario section 'pose': tilt_deg = {tilt} must be in [-90, 90]")
    return Pose.tilted(math.radians(tilt), math.radians(_number("pose", "tilt_axis_deg", tilt_axis_deg)), **place)


def _pose_to_dict(pose: Pose) -> dict:
    return {"magnet_position_m": _floats(pose.magnet_position_m), "theta0_deg": math.degrees(pose.theta0_rad),
            "plane_e1": _floats(pose.plane_e1), "plane_e2": _floats(pose.plane_e2),
            "gravity_m_per_s2": _floats(pose.gravity_m_per_s2)}


def _sensors(pose: Pose, positions_m=None, axis=(0.0, 1.0, 0.0), range_t=FL1_RANGE_T,
             resolution_t=FL1_RESOLUTION_T, null_offsets=True) -> Sensors:
    """Two parallel sensors; by default at the paper's places relative to the magnet's rest position."""
    if positions_m is None:
        positions = FluxgatePair.paper(pose.magnet_position_m).positions_m
    else:
        positions = np.asarray(positions_m, dtype=float)
        if positions.shape != (2, 3):
            raise ValueError(f"scenario section 'sensors': positions_m must be two 3-vectors, got {positions_m!r}")
    if not isinstance(null_offsets, bool):
        raise ValueError(f"scenario section 'sensors': null_offsets must be true or false, got {null_offsets!r}")
    sensors = [Fluxgate(p, axis, _number("sensors", "range_t", range_t),
                        _number("sensors", "resolution_t", resolution_t)) for p in positions]
    return Sensors(FluxgatePair(tuple(sensors)), null_offsets)


def _sensors_to_dict(sensors: Sensors) -> dict:
    near = sensors.pair.sensors[0]
    return {"positions_m": sensors.pair.positions_m.tolist(), "axis": _floats(near.axis),
            "range_t": float(near.range_t), "resolution_t": float(near.resolution_t),
            "null_offsets": sensors.null_offsets}


def _numbers_into(cls):
    """A builder that converts every value to float before calling ``cls`` (same keys)."""
    def build(**values):
        return cls(**{k: _number(cls.__name__.lower(), k, v) for k, v in values.items()})
    build.__signature__ = inspect.signature(cls)
    return build


_noise = _numbers_into(NoiseModel)


def _excitation(amplitude_a=Excitation.amplitude_a, frequency_hz=None, excite_s=Excitation.excite_s,
                ringdown_s=Excitation.ringdown_s, gap_s=Excitation.gap_s) -> Excitation:
    values = {k: _number("excitation", k, v) for k, v in
              dict(amplitude_a=amplitude_a, excite_s=excite_s, ringdown_s=ringdown_s, gap_s=gap_s).items()}
    frequency = None if frequency_hz is None else _number("excitation", "frequency_hz", frequency_hz)
    return Excitation(frequency_hz=frequency, **values)
