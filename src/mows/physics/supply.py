"""The static-field power supply of the calibration (paper, Methods and Fig. 3).

The paper calibrates a probe in the homogeneous field of a Helmholtz pair (and the gradient of
the same pair anti-parallel) driven by a DC supply of 0.1 mA resolution and 2 A maximum.
:class:`SupplyLimits` is what the driver and the device agree on: currents above the cap are
refused (never clipped), a setting is rounded to the resolution, and the current changes no
faster than the slew limit (a coil pair is an inductance: a step would induce a voltage spike
and, in the probe, a field step that rings it). :meth:`SupplyLimits.ramp` gives the staircase
that the device walks from one current to the next.

A supply is ``bipolar`` (it sources either sign, −cap … +cap) or ``unipolar`` (0 … +cap, as the
paper's NGM202 and most laboratory supplies): a negative set-point on a unipolar supply is
refused like one above the cap. A calibration on a unipolar supply gets the field's other sign
from the probe's orientation instead (θ0 and θ0 + 180°; :mod:`mows.sweep.calibration.schedule`).

:class:`FieldSupply` is the supply in a scenario: the field source it drives per ampere and its
limits (YAML: the scenario section ``supply``, docs/scenario_format.md).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.physics.field import FieldSource, source_from_dict, source_to_dict
from mows.physics.schema import check_keys, refused

PAPER_CAP_A = 2.0  # Methods: the supply's maximum
PAPER_RESOLUTION_A = 1e-4  # Methods: 0.1 mA
DEFAULT_SLEW_A_PER_S = 2.0  # assumed: full scale in one second
RAMP_STEP_S = 0.01  # the staircase of a ramp changes the current every 10 ms
POLARITIES = ("bipolar", "unipolar")


@dataclasses.dataclass(frozen=True)
class SupplyLimits:
    """Cap, slew limit, resolution and polarity (``bipolar`` or ``unipolar``) of a field
    supply, SI units."""

    cap_a: float = PAPER_CAP_A
    slew_a_per_s: float = DEFAULT_SLEW_A_PER_S
    resolution_a: float = PAPER_RESOLUTION_A
    polarity: str = "bipolar"

    def __post_init__(self) -> None:
        for name in ("cap_a", "slew_a_per_s", "resolution_a"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f"supply: {name} = {value!r} must be a finite number > 0")
        if self.resolution_a > self.cap_a:
            raise ValueError(f"supply: resolution_a = {self.resolution_a} exceeds cap_a = {self.cap_a}")
        if self.polarity not in POLARITIES:
            raise ValueError(f"supply: polarity = {self.polarity!r} must be one of {', '.join(POLARITIES)}")

    def range_a(self, cap_a: float = math.inf) -> tuple[float, float]:
        """(lowest, highest) current it sources under the lower of its cap and ``cap_a``:
        the lowest is 0 for a unipolar supply."""
        high = min(self.cap_a, cap_a)
        return (0.0 if self.polarity == "unipolar" else -high), high

    @property
    def min_current_a(self) -> float:
        return self.range_a()[0]

    @property
    def range_text(self) -> str:
        """The currents it sources, for messages: ``0 … +2 A (unipolar)``, ``-2 … +2 A (bipolar)``."""
        low, high = self.range_a()
        return f"{low:g} … {high:+g} A ({self.polarity})"

    def check(self, current_a: float) -> float:
        """``current_a`` rounded to the resolution; ValueError if not finite, above the cap or
        (a unipolar supply) negative."""
        if (
            isinstance(current_a, bool)
            or not isinstance(current_a, (int, float, np.integer, np.floating))
            or not math.isfinite(current_a)
        ):
            raise ValueError(f"supply current {current_a!r} must be a finite number of amperes")
        value = float(current_a)
        if abs(value) > self.cap_a:
            raise ValueError(
                f"supply current {value:.6g} A exceeds the cap of {self.cap_a:g} A (refused, never clipped)"
            )
        if value < self.min_current_a:
            raise ValueError(
                f"supply current {value:.6g} A is outside the supply's range {self.range_text} (refused, never sent)"
            )
        return round(value / self.resolution_a) * self.resolution_a

    def ramp_s(self, from_a: float, to_a: float) -> float:
        """Time the slew limit needs from ``from_a`` to ``to_a``, s."""
        return abs(to_a - from_a) / self.slew_a_per_s

    def ramp(self, from_a: float, to_a: float, step_s: float = RAMP_STEP_S) -> list[tuple[float, float]]:
        """The staircase from ``from_a`` to ``to_a`` (checked): (time after the start, s;
        current, A) pairs, each step at most slew·step_s, the last one the target."""
        target = self.check(to_a)
        steps = max(1, math.ceil(self.ramp_s(from_a, target) / step_s - 1e-9))
        currents = [self.check(from_a + (target - from_a) * (k + 1) / steps) for k in range(steps - 1)]
        return [(k * step_s, current) for k, current in enumerate(currents + [target])]


@dataclasses.dataclass(frozen=True, eq=False)
class FieldSupply:
    """A supply driving ``source`` (its field per ampere, global frame) at ``current_a``."""

    source: FieldSource
    limits: SupplyLimits = SupplyLimits()
    current_a: float = 0.0
    name: str = "helmholtz"

    def __post_init__(self) -> None:
        if not isinstance(self.source, FieldSource):
            raise ValueError(f"supply: source must be a field source, got {self.source!r}")
        self.limits.check(self.current_a)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "source": source_to_dict(self.source),
            "current_a": float(self.current_a),
            "cap_a": float(self.limits.cap_a),
            "slew_a_per_s": float(self.limits.slew_a_per_s),
            "resolution_a": float(self.limits.resolution_a),
            # Written when not the default: a bipolar scene's mapping stays as it always was.
            **({"polarity": self.limits.polarity} if self.limits.polarity != "bipolar" else {}),
        }


def supply_from_dict(data: dict) -> FieldSupply:
    """The scenario section ``supply``: ``source`` (the field at 1 A), ``current_a`` at start,
    ``cap_a``, ``slew_a_per_s``, ``resolution_a``, ``polarity`` (``bipolar``, the default, or
    ``unipolar``), ``name``."""
    if not isinstance(data, dict):
        raise refused("", data, "must be a mapping")
    check_keys("", data, _supply)
    return _supply(**data)


def _supply(
    source: dict,
    name: str = "helmholtz",
    current_a: float = 0.0,
    cap_a: float = PAPER_CAP_A,
    slew_a_per_s: float = DEFAULT_SLEW_A_PER_S,
    resolution_a: float = PAPER_RESOLUTION_A,
    polarity: str = "bipolar",
) -> FieldSupply:
    limits = SupplyLimits(float(cap_a), float(slew_a_per_s), float(resolution_a), str(polarity))
    return FieldSupply(source_from_dict(source), limits, float(current_a), str(name))
