"""Simulator scenarios: what is simulated, as dataclasses and as YAML (docs/scenario_format.md).

A scenario fixes the probe, the excitation coil setup, the static environment (field sources,
temperature), where the probe sits and how it is turned (:class:`mows.physics.pose.Pose`), the two
fluxgates, their noise, the default excitation, the housing stop and the integrator. Every
section has defaults; ``Scenario()`` is the paper's probe in the largest-spacing setup with no
environment field and no noise, and ``load_scenario()`` is the documented default scenario
(the paper's device in its largest-spacing setup, in the Earth's field).

YAML keys carry SI unit suffixes; degrees appear only in keys ending ``_deg``; numbers are read
as YAML 1.2 reads them (``1e-8`` is a number, :func:`mows.physics.schema.load_yaml`). Unknown
keys, missing required keys and out-of-range values raise ValueError on one line naming the file,
the key path (``probes[1].pose.magnet_position_m``), the value and what is allowed.
Shipped scenarios live in ``src/mows/sim/scenarios/<name>.yaml`` and are loaded by name. A
scenario may ``extends:`` another (a shipped name or a YAML path): its mapping is deep-merged
over the base's, so the shipped scenes state only how they differ from ``base.yaml``.

The sections' dataclasses are :mod:`mows.sim.sections`, the YAML reading (``extends:``, the
section builders) :mod:`mows.sim.scenario_yaml`; this module assembles them into a Scenario.
"""

from __future__ import annotations

import dataclasses
import functools
import pathlib
from collections.abc import Iterable

import numpy as np
import yaml

from mows.physics.coils import CoilSetup, largest_spacing, setup_from_dict
from mows.physics.coupling import PlacedProbe, check_apart
from mows.physics.field import source_to_dict
from mows.physics.fluxgate import DAQ_SAMPLE_RATE_HZ, NoiseModel
from mows.physics.multitone import MAX_PROBES
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE, Probe
from mows.physics.schema import at, check_keys, finite_number, load_yaml, refused
from mows.physics.supply import FieldSupply, supply_from_dict
from mows.records.files import writing
from mows.sim.scenario_yaml import (
    PAPER_PROBE_NAME,
    SCENARIO_DIR,
    environment_from,
    excitation_from,
    noise_from,
    numbers_into,
    pose_from,
    pose_to_dict,
    probe_from,
    probes_from,
    require_explicit_geometry,
    section,
    sensors_from,
    sensors_to_dict,
    shipped_scenarios,
    with_bases,
)
from mows.sim.sections import Environment, Excitation, Housing, Integrator, SceneProbe, Sensors, check_range

DEFAULT_SCENARIO = "paper_largest_spacing"


@dataclasses.dataclass(frozen=True, eq=False)
class Scenario:
    """Everything the simulator needs (module docstring); build variants with :meth:`replace`."""

    # The scene's probes (docs/multi_probe.md), one or several: a scene of one probe is a group
    # of one. The first is the scene's ``probe`` at its ``pose``: the coil preset and the sensors
    # sit around it.
    probes: tuple[SceneProbe, ...] = (SceneProbe(PAPER_PROBE, Pose()),)
    setup: CoilSetup = dataclasses.field(default_factory=largest_spacing)
    environment: Environment = Environment()
    sensors: Sensors = dataclasses.field(default_factory=Sensors)
    noise: NoiseModel = NoiseModel()
    excitation: Excitation = Excitation()
    housing: Housing = Housing()
    integrator: Integrator = Integrator()
    sample_rate_hz: float = DAQ_SAMPLE_RATE_HZ
    seed: int = 1
    name: str = "custom"
    description: str = ""
    supply: FieldSupply | None = None  # the static-field supply the driver controls (calibration)

    def __post_init__(self):
        if not 1 <= len(self.probes) <= MAX_PROBES:
            raise refused("probes", len(self.probes), f"must be 1 to {MAX_PROBES} probes")
        check_apart(self.placed_probes(), [f"probes[{k}].pose.magnet_position_m" for k in range(len(self.probes))])
        check_range("sample_rate_hz", self.sample_rate_hz, 0.0, 1e7, low_open=True)
        if isinstance(self.seed, bool) or not isinstance(self.seed, (int, np.integer)) or self.seed < 0:
            raise refused("seed", self.seed, "must be an integer ≥ 0")
        self.setup.cap.check(self.excitation.amplitude_a)

    @property
    def probe(self) -> Probe:
        """The first probe's constants (the scene's probe that the coils and sensors sit around)."""
        return self.probes[0].probe

    @property
    def pose(self) -> Pose:
        """The first probe's pose."""
        return self.probes[0].pose

    def placed_probes(self, theta0_rad=None) -> list[PlacedProbe]:
        """Every probe of the scene at its pose, turned to ``theta0_rad`` (one θ0 per probe;
        default: their home orientations)."""
        angles = [None] * len(self.probes) if theta0_rad is None else list(theta0_rad)
        if len(angles) != len(self.probes):
            raise ValueError(
                f"theta0_rad = {theta0_rad!r} must give one angle for each of the {len(self.probes)} probes"
            )
        return [p.placed(a) for p, a in zip(self.probes, angles)]

    def stage_orientations_rad(self, stage_rad: float) -> np.ndarray:
        """Each probe's θ0 with the shared stage at ``stage_rad``: its home orientation plus it
        (the driver's θ0 is the probe's orientation where the probe's home is 0, as in every
        shipped scene of one probe)."""
        return np.array([p.pose.theta0_rad for p in self.probes]) + float(stage_rad)

    def replace(self, **changes) -> Scenario:
        """A variant with ``changes``; ``probe`` and ``pose`` change the first probe's."""
        if "probe" in changes or "pose" in changes:
            first = self.probes[0]
            first = dataclasses.replace(
                first, probe=changes.pop("probe", first.probe), pose=changes.pop("pose", first.pose)
            )
            if "probes" in changes:
                raise ValueError("give either probes or the first probe's probe and pose, not both")
            changes["probes"] = (first, *self.probes[1:])
        return dataclasses.replace(self, **changes)

    # --- YAML ---------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: dict, base_dir=None) -> Scenario:
        """Scenario from its YAML mapping; probe file paths and an ``extends:`` file path are
        relative to ``base_dir`` (in a base file: to that file's folder)."""
        data = with_bases(data, base_dir)
        check_keys("", data, _scenario_from_sections)
        return _scenario_from_sections(**data)

    def to_dict(self) -> dict:
        """The full YAML mapping (presets and the paper probe written out in full)."""
        return {
            "name": self.name,
            "description": self.description,
            "probes": [_probe_entry(p) for p in self.probes],
            "setup": self.setup.to_dict(),
            "environment": {
                "sources": [source_to_dict(s) for s in self.environment.sources],
                "temperature_k": float(self.environment.temperature_k),
                "temperature_rate_k_per_s": float(self.environment.temperature_rate_k_per_s),
            },
            "sensors": sensors_to_dict(self.sensors),
            "noise": {k: float(v) for k, v in dataclasses.asdict(self.noise).items()},
            "excitation": dataclasses.asdict(self.excitation),
            "housing": dataclasses.asdict(self.housing),
            "integrator": dataclasses.asdict(self.integrator),
            "sample_rate_hz": float(self.sample_rate_hz),
            "seed": int(self.seed),
            **({} if self.supply is None else {"supply": self.supply.to_dict()}),
        }

    @classmethod
    def from_yaml(cls, path) -> Scenario:
        """The scenario file at ``path``; ValueError naming the file, the key path and the value."""
        path = pathlib.Path(path)
        return load_yaml(path, "scenario", lambda data: cls.from_dict(data, base_dir=path.parent))

    def to_yaml(self, path, inputs: Iterable = (), force: bool = False) -> str:
        """Write the scenario as a new file, never over ``inputs`` nor, unless ``force``, over an
        existing one (:func:`mows.records.files.writing`); "wrote PATH" or "replaced PATH"."""
        with writing([path], inputs, force) as outputs:
            outputs.temporaries[0].write_text(yaml.safe_dump(self.to_dict(), sort_keys=False))
        return outputs.report()


def load_scenario(name_or_path=DEFAULT_SCENARIO) -> Scenario:
    """A shipped scenario by name (``src/mows/sim/scenarios/<name>.yaml``) or a YAML file by path."""
    return Scenario.from_yaml(scenario_file(name_or_path))


def scenario_file(name_or_path=DEFAULT_SCENARIO) -> pathlib.Path:
    """The file a scenario's name or path stands for (a name is no path in the working directory)."""
    path = pathlib.Path(name_or_path)
    if path.suffix not in (".yaml", ".yml"):
        path = SCENARIO_DIR / f"{name_or_path}.yaml"
        if not path.is_file():
            raise ValueError(
                f"scenario {name_or_path!r} is neither a YAML file nor one of the shipped "
                f"scenarios {shipped_scenarios()}"
            )
    return path


def _at(key: str, build, data):
    """``build(data)``, a refusal inside being at ``key``."""
    with at(key):
        return build(data)


def _probe_entry(scene_probe: SceneProbe) -> dict:
    return {"probe": scene_probe.probe.to_dict(), "pose": pose_to_dict(scene_probe.pose), "stage": scene_probe.stage}


# --- the whole mapping: the signature is the scenario's top-level YAML keys ------------------
def _scenario_from_sections(
    name="custom",
    description="",
    probe=PAPER_PROBE_NAME,
    setup=None,
    environment=None,
    pose=None,
    sensors=None,
    noise=None,
    excitation=None,
    housing=None,
    integrator=None,
    sample_rate_hz=Scenario.sample_rate_hz,
    seed=Scenario.seed,
    supply=None,
    probes=None,
) -> Scenario:
    scene_probes = _scene_probes(probe, pose, probes)
    the_pose = scene_probes[0].pose
    fs = finite_number("sample_rate_hz", sample_rate_hz)
    setup = {"preset": "largest_spacing"} if setup is None else setup
    require_explicit_geometry(the_pose, setup, sensors)
    if isinstance(setup, dict) and "preset" in setup:  # the preset's coils sit around the probe
        setup = {"probe_position_m": list(the_pose.magnet_position_m), **setup}
    return Scenario(
        probes=scene_probes,
        setup=_at("setup", setup_from_dict, setup),
        environment=section("environment", environment, environment_from),
        sensors=section("sensors", sensors, functools.partial(sensors_from, the_pose)),
        noise=section("noise", noise, noise_from),
        excitation=section("excitation", excitation, excitation_from),
        housing=section("housing", housing, numbers_into(Housing)),
        integrator=section("integrator", integrator, Integrator),
        sample_rate_hz=fs,
        seed=seed,
        name=str(name),
        description=str(description),
        supply=None if supply is None else _at("supply", supply_from_dict, supply),
    )


def _scene_probes(probe, pose, probes) -> tuple[SceneProbe, ...]:
    """The scene's probes: the ``probes:`` list, or the older shape's ``probe`` at ``pose`` read
    as a group of one (a probe on its own stage)."""
    if probes is None:
        return (SceneProbe(probe_from(probe), section("pose", pose, pose_from)),)
    if pose is not None or probe != PAPER_PROBE_NAME:
        raise ValueError("give either probe and pose (the older shape of one probe) or probes, not both")
    return probes_from(probes)
