"""Where the model fails and which effect is missing: the diagnosis of one fit, and its verdict.

:func:`diagnose` runs the steps in order: the residual structure (:mod:`mows.lab.diagnosis.residual_structure`),
the candidates (:mod:`mows.lab.diagnosis.candidates`), their groups and separating measurements
(:mod:`mows.lab.diagnosis.indistinguishable`), then the verdict:

- ``effect_missing`` when the best candidate has ΔBIC > 10, p < 1e-3 and accounts for at least
  half of the excess χ² − dof;
- else ``adequate`` when χ² is consistent with its dof (p ≥ 0.005) and no structure is
  significant;
- else ``unexplained_structure``.

:func:`mows.lab.report.lab_report.analyse` turns ``adequate`` into ``inconsistent_physics`` or
``needs_generic_term`` when the physics checks say so.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Iterable

from mows.lab.diagnosis.candidates import Candidate, rank_candidates
from mows.lab.diagnosis.indistinguishable import Group, absorbed_groups, group_candidates
from mows.lab.diagnosis.residual_structure import (
    GOODNESS_ALPHA,
    Structure,
    plugin_expression,
    product_trends,
    residual_structure,
)
from mows.lab.model.effects import Effect
from mows.lab.model.least_squares import FitResult
from mows.physics.probe import Probe

EXPLAINED_FRACTION = 0.5
FIELD_SPRINGS = ("b_along_t", "g_t_per_m")  # covariates that are the model's own magnetic springs
SLOW_COVARIATES = ("temperature_k", "t_s")  # what a spring drifts with


class Verdict(enum.StrEnum):
    """The lab's answer on a model (module docstring); printed, in JSON and in
    mows_msgs/ModelReport as its value."""

    EFFECT_MISSING = "effect_missing"
    ADEQUATE = "adequate"
    UNEXPLAINED_STRUCTURE = "unexplained_structure"
    INCONSISTENT_PHYSICS = "inconsistent_physics"
    NEEDS_GENERIC_TERM = "needs_generic_term"


@dataclasses.dataclass
class Diagnosis:
    fit: FitResult
    structure: Structure
    candidates: list[Candidate]
    groups: list[Group]
    untestable: dict[str, str]  # effect name → why it cannot be tested
    verdict: Verdict
    explanation: str

    @property
    def best(self) -> Candidate | None:
        return self.candidates[0] if self.candidates else None


def diagnose(fit: FitResult, effects: Iterable[Effect], probe: Probe | None = None) -> Diagnosis:
    """Rank ``effects`` (an iterable of :class:`Effect`, those already in the model are skipped)
    as explanations of ``fit``'s residual; group, propose separating measurements, verdict."""
    probe = probe or fit.model.probe
    assert probe is not None  # a model that was fitted has its probe
    effects = list(effects)
    candidates, untestable = rank_candidates(fit, effects, probe)
    groups = group_candidates(candidates, fit, probe)
    groups += absorbed_groups(fit, effects, candidates, untestable, probe, len(groups) + 1)
    structure = residual_structure(fit)
    verdict, explanation = _verdict(fit, structure, candidates)
    return Diagnosis(fit, structure, candidates, groups, untestable, verdict, explanation)


# --- verdict ------------------------------------------------------------------------------------
def _verdict(fit: FitResult, structure: Structure, candidates: list[Candidate]) -> tuple[Verdict, str]:
    best = candidates[0] if candidates else None
    excess = fit.chi2 - fit.dof
    if best is not None and best.strong:
        gain = fit.chi2 - best.chosen.chi2_after
        if gain >= EXPLAINED_FRACTION * excess:
            group = (
                f" (group {best.group}: the data cannot tell it from "
                f"{', '.join(c.name for c in candidates if c.group == best.group and c is not best)})"
                if best.group
                else ""
            )
            return Verdict.EFFECT_MISSING, (
                f"{best.label} is missing{group}: ΔBIC = {best.delta_bic:.1f}, "
                f"p = {best.p_value:.1e}, "
                f"χ²/dof {fit.chi2_dof:.3g} → {best.chi2_dof_after:.3g}."
            )
        unexplained = (
            f"The best candidate, {best.label} (ΔBIC = {best.delta_bic:.1f}), accounts for only "
            f"{100 * gain / excess:.0f}% of the excess χ². "
        )
    elif best is not None:
        unexplained = (
            f"No catalog effect explains the residual: judged against the residual's own scatter (Δχ² "
            f"scaled by the χ²/dof each candidate leaves), the best, {best.label}, reaches ΔBIC "
            f"{best.delta_bic:.1f} (χ²/dof {fit.chi2_dof:.3g} → {best.chi2_dof_after:.3g})."
        )
    else:
        unexplained = ""
    if structure.goodness_p >= GOODNESS_ALPHA and not structure.significant:
        return Verdict.ADEQUATE, "The model explains the data: " + structure.summary
    found = unexplained + " " + structure.summary + " " + _no_answer(fit, structure)
    return Verdict.UNEXPLAINED_STRUCTURE, found.strip()


def _no_answer(fit: FitResult, structure: Structure) -> str:
    """What the residual follows when no catalog effect explains it (single covariates and
    products of two, angle harmonics included), and the plugin a user would write for the
    strongest (docs/model_lab.md)."""
    trends = sorted(structure.covariates + product_trends(fit), key=lambda trend: -abs(trend.correlation))
    if not trends:
        return ""
    follows = "; ".join(f"{t.name} (correlation {t.correlation:+.2f}, p = {t.p_value:.1e})" for t in trends[:3])
    return (
        f"The residual follows {follows}. A plugin for the strongest, to save as my_effect.py and run with "
        "--plugin my_effect.py: `{}` ({}).".format(*plugin_sketch(trends[0].name))
    )


def plugin_sketch(trend: str) -> tuple[str, str]:
    """(plugin source on one line, why that form) for a residual that follows ``trend`` (a covariate or a
    product ``a·b``): the physical change where one fits (a field spring that changes with a
    covariate is the moment changing with it; a drift of one covariate alone is the spring
    changing with it), else an additive frequency term."""
    factors = trend.split("·")
    others = [f for f in factors if f not in FIELD_SPRINGS]
    if len(factors) == 2 and len(others) == 1 and not others[0].endswith("θ0)"):
        output, parameter, unit, bound = "moment_scale", "c", "1", 1.0
        expression = f"(rows.{others[0]} - rows.{others[0]}.mean())"
        why = "the field's spring m·Bx' changes with it: the moment does"
    elif len(factors) == 1 and factors[0] in SLOW_COVARIATES:
        output, parameter, unit, bound = "stiffness_nm_per_rad", "c_nm_per_rad", "N·m/rad", 1e-6
        expression = f"(rows.{factors[0]} - rows.{factors[0]}.mean())"
        why = "the spring drifts with it"
    else:
        output, parameter, unit, bound = "frequency_hz", "c_hz", "Hz", 1.0
        expression = " * ".join(plugin_expression(factor) for factor in factors)
        why = "better: the physics that makes it"
    return (
        f'import numpy as np; from mows.lab import effect; @effect(name="my_effect", '
        f'parameters={{"{parameter}": (0.0, -{bound:g}, {bound:g}, "{unit}")}}) def my_effect(rows, {parameter}): '
        f'return {{"{output}": {parameter} * {expression}}}',
        why,
    )
