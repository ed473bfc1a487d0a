"""The scenario's own sections (those without a dataclass elsewhere in mows.physics): the
environment, the sensors, the default excitation, the housing stop and the integrator, each
checking its ranges (ValueError naming the key and the value). :class:`mows.sim.scenario.Scenario`
holds them; :mod:`mows.sim.scenario_yaml` builds them from YAML.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.physics import ranges
from mows.physics.coupling import PlacedProbe
from mows.physics.field import FieldSource, SumSource
from mows.physics.fluxgate import FluxgatePair
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE, Probe
from mows.physics.schema import is_number, refused

#: How a probe of a scene with several is turned: by a stage of its own, or by the one stage
#: all "shared" probes sit on (each keeps its own θ0 on it, turned by the same angle).
STAGES = ("own", "shared")


def check_range(key, value, low, high, low_open=False):
    """:class:`mows.physics.schema.SchemaError` naming the key and value unless low ≤ value ≤ high
    (low < value if ``low_open``); the section's name is added on the way out of its YAML."""
    ok = math.isfinite(value) and (low < value if low_open else low <= value) and value <= high
    if not ok:
        bracket = "(" if low_open else "["
        raise refused(key, value, f"is out of range {bracket}{low:g}, {high:g}]")


def floats(vector) -> list:
    return [float(v) for v in vector]


@dataclasses.dataclass(frozen=True, eq=False)
class Environment:
    """The static surroundings: field sources (global frame) and the temperature.

    ``temperature_k`` at device time 0 drifts linearly at ``temperature_rate_k_per_s``; the
    probe's kM follows it (docs/physics.md §9.6, :meth:`mows.physics.probe.Probe.spring_at`).
    """

    sources: tuple = ()
    temperature_k: float = PAPER_PROBE.reference_temperature_k
    temperature_rate_k_per_s: float = 0.0

    def __post_init__(self):
        object.__setattr__(self, "sources", tuple(self.sources))
        if not all(isinstance(s, FieldSource) for s in self.sources):
            raise ValueError(f"environment sources must be field sources, got {self.sources!r}")
        check_range("temperature_k", self.temperature_k, 0.0, math.inf, low_open=True)
        ranges.check("temperature_k", self.temperature_k)
        check_range("temperature_rate_k_per_s", self.temperature_rate_k_per_s, -1.0, 1.0)

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
        check_range("amplitude_a", self.amplitude_a, 0.0, math.inf)
        if self.frequency_hz is not None:
            check_range("frequency_hz", self.frequency_hz, 0.0, math.inf, low_open=True)
        check_range("excite_s", self.excite_s, 0.0, 3600.0)
        check_range("ringdown_s", self.ringdown_s, 0.0, 3600.0, low_open=True)
        check_range("gap_s", self.gap_s, 0.0, 3600.0)


@dataclasses.dataclass(frozen=True)
class SceneProbe:
    """One probe of a scene: its constants, its pose (where its magnet rests, its
    rotation plane and its home orientation θ0) and the stage that turns it (``STAGES``)."""

    probe: Probe
    pose: Pose
    stage: str = "own"

    def __post_init__(self):
        if self.stage not in STAGES:
            raise refused("stage", self.stage, f"must be one of {STAGES}")

    def placed(self, theta0_rad: float | None = None) -> PlacedProbe:
        """The probe at its pose, turned to ``theta0_rad`` (default: its home orientation)."""
        pose = self.pose if theta0_rad is None else self.pose.with_theta0(theta0_rad)
        return PlacedProbe(self.probe, pose)


@dataclasses.dataclass(frozen=True)
class Housing:
    """The housing stop at ±θstop as a stiff spring–dashpot contact (see :mod:`mows.sim.kernel`).

    ``stiffness_ratio``: contact stiffness over kM; ``restitution``: coefficient of
    restitution of one impact (sets the contact damping).
    """

    stiffness_ratio: float = 1000.0
    restitution: float = 0.5

    def __post_init__(self):
        check_range("stiffness_ratio", self.stiffness_ratio, 10.0, 1e5)
        check_range("restitution", self.restitution, 0.0, 1.0, low_open=True)


@dataclasses.dataclass(frozen=True)
class Integrator:
    """RK4 steps per sample: ``substeps`` in free flight, ``contact_substeps`` near the stop."""

    substeps: int = 2
    contact_substeps: int = 16

    def __post_init__(self):
        for name in ("substeps", "contact_substeps"):
            value = getattr(self, name)
            if not (is_number(value) and isinstance(value, (int, np.integer)) and 1 <= value <= 1000):
                raise refused(name, value, "must be an integer in [1, 1000]")
