"""Where the model fails and which effect is missing: the diagnosis of one fit, and its verdict.

:func:`diagnose` runs the steps in order: the residual structure (:mod:`mows.lab.diagnosis.residual_structure`),
the candidates (:mod:`mows.lab.diagnosis.candidates`), their groups and separating measurements
(:mod:`mows.lab.diagnosis.indistinguishable`), then the verdict:

- ``effect_missing`` when the best candidate has ΔBIC > 10, p < 1e-3 and accounts for at least
  half of the excess χ² − dof;
- else ``adequate`` when χ² is consistent with its dof (p ≥ 0.005) and no structure is
  significant;
- else ``unexplained_structure``; then the search beyond the catalog
  (:func:`mows.lab.diagnosis.discovery.discover`) names the terms of the rows' covariates the
  residual follows, and the explanation gives the strongest one's plugin in its physical form.

:func:`mows.lab.report.lab_report.analyse` turns ``adequate`` into ``inconsistent_physics`` or
``needs_generic_term`` when the physics checks say so.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Iterable

from mows.lab.data.probe_rows import ProbeSet
from mows.lab.diagnosis.candidates import STRONG_DELTA_BIC, Candidate, explains_excess, rank_candidates
from mows.lab.diagnosis.discovery import WHY, DiscoveredTerm, Discovery, discover
from mows.lab.diagnosis.indistinguishable import Group, absorbed_groups, group_candidates
from mows.lab.diagnosis.missing import is_missing
from mows.lab.diagnosis.residual_structure import (
    GOODNESS_ALPHA,
    Structure,
    plugin_expression,
    product_trends,
    residual_structure,
)
from mows.lab.model.effects import Effect
from mows.lab.model.least_squares import FitResult

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
    discovery: Discovery | None = None  # beyond the catalog: for unexplained structure

    @property
    def best(self) -> Candidate | None:
        return self.candidates[0] if self.candidates else None


def diagnose(fit: FitResult, effects: Iterable[Effect], probes: ProbeSet, for_report: bool = True) -> Diagnosis:
    """Rank ``effects`` (an iterable of :class:`Effect`, those already in the model are skipped)
    as explanations of ``fit``'s residual; group, propose separating measurements, verdict.
    ``for_report=False`` leaves out what only a report reads (the separating measurements, the
    groups of effects the model absorbs, the discovery beyond the catalog): a search step's."""
    effects = list(effects)
    candidates, untestable = rank_candidates(fit, effects, probes)
    return _diagnosis(fit, effects, probes, candidates, untestable, for_report)


def completed(found: Diagnosis, effects: Iterable[Effect], probes: ProbeSet) -> Diagnosis:
    """A search step's diagnosis (``for_report=False``) with what a report reads added."""
    return _diagnosis(found.fit, list(effects), probes, found.candidates, found.untestable, True)


def _diagnosis(
    fit: FitResult,
    effects: list[Effect],
    probes: ProbeSet,
    candidates: list[Candidate],
    untestable: dict[str, str],
    for_report: bool,
) -> Diagnosis:
    groups = group_candidates(candidates, fit, probes, separate=for_report)
    if for_report:
        groups += absorbed_groups(fit, effects, candidates, untestable, probes, len(groups) + 1)
    structure = residual_structure(fit)
    verdict, explanation = _verdict(fit, structure, candidates, probes)
    if verdict != Verdict.UNEXPLAINED_STRUCTURE or not for_report:
        return Diagnosis(fit, structure, candidates, groups, untestable, verdict, explanation)
    discovery = discover(fit, probes)
    explanation = f"{explanation} {_no_answer(fit, structure, discovery)}".strip()
    return Diagnosis(fit, structure, candidates, groups, untestable, verdict, explanation, discovery)


# --- verdict ------------------------------------------------------------------------------------
def _verdict(
    fit: FitResult, structure: Structure, candidates: list[Candidate], probes: ProbeSet
) -> tuple[Verdict, str]:
    """The verdict and its explanation; for ``unexplained_structure`` without what the residual
    follows (:func:`_no_answer` adds it). The best candidate is missing by the search's own
    judgement (:func:`mows.lab.diagnosis.missing.is_missing`) and when it explains half the excess."""
    best = candidates[0] if candidates else None
    excess = fit.chi2 - fit.dof
    if best is not None and best.strong:
        gain = fit.chi2 - best.chosen.chi2_after
        explains = explains_excess(fit, best.chosen)
        if explains and is_missing(fit, best, probes):
            group = (
                f" (group {best.group}: the data cannot tell it from "
                f"{', '.join(c.name for c in candidates if c.group == best.group and c is not best)})"
                if best.group
                else ""
            )
            return Verdict.EFFECT_MISSING, (
                f"{best.label} is missing{group}: ΔBIC = {best.delta_bic:.1f}, "
                f"p = {best.p_value:.1e}, "
                f"χ²/dof {fit.chi2_dof:.3g} → {best.chi2_dof_after:.3g}." + _findings(candidates)
            )
        if not explains:
            why = f"accounts for only {100 * gain / excess:.0f}% of the excess χ²"
        elif best.effect.generic:
            why = "is a generic correction that leaves structure: it would take a share of physics it is not"
        else:
            why = (
                "leaves structure that terms beyond the catalog explain, and has no strong evidence of its own "
                "beside them, or does not predict the configurations it was not fitted to"
            )
        unexplained = (
            f"The best candidate, {best.label} (ΔBIC = {best.delta_bic:.1f}, χ²/dof {fit.chi2_dof:.3g} → "
            f"{best.chi2_dof_after:.3g}), {why}. "
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
    found = unexplained + " " + structure.summary + _findings(candidates)
    return Verdict.UNEXPLAINED_STRUCTURE, found.strip()


def _findings(candidates: list[Candidate]) -> str:
    """The candidates the data ask for strongly only at values physics does not allow: each is a
    finding (the probe file's or the reference's value is off, or physics outside the catalog
    looks like the effect), not an effect."""
    found = [c for c in candidates if c.would_need and c.delta_bic > STRONG_DELTA_BIC]
    return "".join(
        f" Finding: {c.label} would take ΔBIC {c.delta_bic:.0f} but {c.would_need}: the probe file's or "
        "the reference's value is off by that much, or physics outside the catalog looks like it."
        for c in found
    )


def _no_answer(fit: FitResult, structure: Structure, discovery: Discovery) -> str:
    """What the residual follows when no catalog effect explains it: the terms the search beyond
    the catalog found, with the strongest one's plugin in its physical form, then the strongest
    trends with single covariates and products of two (angle harmonics included); without a
    discovered term, the plugin a user would write for the strongest trend (docs/model_lab.md)."""
    trends = sorted(structure.covariates + product_trends(fit), key=lambda trend: -abs(trend.correlation))
    follows = "; ".join(f"{t.name} (correlation {t.correlation:+.2f}, p = {t.p_value:.1e})" for t in trends[:3])
    found = [discovery.summary]
    if discovery.terms:
        found.append(_discovered_plugin(discovery.terms[0]))
    if trends:
        found.append(f"The residual follows {follows}.")
    if trends and not discovery.terms:
        found.append(
            "A plugin for the strongest, to save as my_effect.py and run with --plugin my_effect.py: `{}` ({}).".format(
                *plugin_sketch(trends[0].name)
            )
        )
    return " ".join(found)


def _discovered_plugin(term: DiscoveredTerm) -> str:
    """The hint for a discovered term: its plugin on one line and the parameter it fits here."""
    fitted = "" if term.plugin_parameter is None else f"; on this table {term.plugin_parameter.text()}"
    return (
        f"A plugin for the strongest, in its physical form, to save as {term.effect_name}.py and run with "
        f"--plugin {term.effect_name}.py: `{term.plugin_line}` ({WHY[term.plugin_output]}{fitted})."
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
