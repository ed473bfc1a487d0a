"""What physics allows a fit to claim: every fitted parameter against its physical value.

A free parameter absorbs whatever structure its signature can reach, physics or not: where the
missing physics is outside the catalog, a least-squares search will happily "explain" it by a
13 % error of m/kM that the probe's calibration rules out, or a tilt of a level plane. So the
search and the verdict hold every fit to physics and to what the user stated:

- each parameter with a prior (:attr:`mows.lab.model.effects.Effect.prior`, (centre, σ): a
  strength of 1 ± 1 %, m/kM within the probe file's calibration σ, the housing stop within its
  stated σ, the spring's temperature coefficient within that of spring steels, the field's
  curvature within what the reference's sources make over the probe's placement where a field
  source gives the reference) must lie within ``IMPOSSIBLE_SIGMAS`` of it, its own σ and the
  prior's combined;
- gravity's in-plane part is that of a unit vector: |d| ≤ 1 (the size a·g·l is known, only the
  direction of "down" is free);
- gravity and a plane tilt, both in a model, must describe one tilt of the rotation plane
  against the level reference: rotating the frame by (t_x, t_y) puts gravity's in-plane part at
  d = (−t_y, t_x).

A fit that fails is not physics: the search does not take it, and the report says what it would
need ("would need moment_scale.scale_error = +0.131 ± 0.002, 13.0 σ from its physics …"): the
finding is the disagreement, not the effect.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.lab.data.probe_rows import ProbeSet
from mows.lab.data.table import MeasurementTable
from mows.lab.model.configuration import rotation_matrix
from mows.lab.model.effects import Effect
from mows.lab.model.least_squares import FitResult, FittedParameter

IMPOSSIBLE_SIGMAS = 3.0


@dataclasses.dataclass(frozen=True)
class Conflict:
    """A fitted value that physics does not allow: ``sigmas`` from ``physics`` ± ``physics_std``."""

    parameter: str
    value: float
    std: float
    physics: float
    physics_std: float
    sigmas: float

    @property
    def text(self) -> str:
        return (
            f"would need {self.parameter} = {self.value:+.4g} ± {self.std:.2g}, {self.sigmas:.1f} σ from its "
            f"physics ({self.physics:+.4g} ± {self.physics_std:.2g})"
        )

    def to_dict(self) -> dict[str, float | str]:
        return {
            "parameter": self.parameter,
            "value": self.value,
            "std": self.std,
            "physics": self.physics,
            "physics_std": self.physics_std,
            "sigmas": self.sigmas,
            "text": self.text,
        }


def conflicts(fit: FitResult, probes: ProbeSet) -> list[Conflict]:
    """Every parameter of ``fit`` that physics does not allow (module docstring), worst first."""
    found = [
        c
        for effect in fit.model.effects
        for c in effect_conflicts(effect, fit.effect_parameters(effect.name), probes, fit.table)
    ]
    return sorted(found + _gravity_conflicts(fit), key=lambda c: -c.sigmas)


def effect_conflicts(
    effect: Effect, fitted: list[FittedParameter], probes: ProbeSet, table: MeasurementTable
) -> list[Conflict]:
    """The parameters of one effect, ``fitted`` (a fit's or a one-step estimate's on ``table``),
    that its prior rules out."""
    if effect.prior is None or not fitted:
        return []
    return [
        dataclasses.replace(conflict, parameter=f"{effect.name}.{parameter.name}")
        for parameter, prior in zip(fitted, effect.prior(probes.first, table))
        if prior is not None and (conflict := _against(parameter, *prior)) is not None
    ]


def _against(parameter: FittedParameter, centre: float, spread: float) -> Conflict | None:
    combined = math.hypot(parameter.std, spread) if math.isfinite(parameter.std) else spread
    sigmas = abs(parameter.value - centre) / combined if combined > 0 else math.inf
    if sigmas <= IMPOSSIBLE_SIGMAS:
        return None
    return Conflict(parameter.name, parameter.value, parameter.std, centre, spread, sigmas)


def _gravity_conflicts(fit: FitResult) -> list[Conflict]:
    """|d| ≤ 1, and one tilt for gravity and a plane tilt (module docstring)."""
    names = fit.model.effect_names
    if "gravity" not in names:
        return []
    down = fit.effect_parameters("gravity")
    d = np.array([p.value for p in down])
    d_std = np.array([p.std for p in down])
    size = float(np.linalg.norm(d))
    size_std = float(np.linalg.norm(d * d_std) / size) if size > 0 else float(np.max(d_std))
    found = []
    if size > 1.0 and (size - 1.0) > IMPOSSIBLE_SIGMAS * size_std:
        found.append(Conflict("|gravity.down|", size, size_std, 1.0, 0.0, (size - 1.0) / size_std))
    if "plane_tilt" in names and not any(e.fixed for e in fit.model.effects if e.name == "plane_tilt"):
        tilt = fit.effect_parameters("plane_tilt")
        implied = rotation_matrix((tilt[0].value, tilt[1].value, 0.0)) @ np.array([0.0, 0.0, -1.0])
        implied_std = (tilt[1].std, tilt[0].std)  # to first order in the tilt
        for parameter, value, std in zip(down, implied, implied_std):
            conflict = _against(parameter, value, std)
            if conflict is not None:
                found.append(dataclasses.replace(conflict, parameter=f"gravity.{parameter.name} (the plane tilt's)"))
    return found
