"""One call from a table to a verdict: fit, diagnose, add effects, error history (the live API).

:func:`analyse` is what the mapper node calls after every sweep; :class:`LabReport` maps onto
``mows_msgs/ModelReport`` (model, effects, n, chi2_dof, bic, cv_rms_hz, verdict, structure,
candidates) and each :class:`mows.lab.diagnose.Candidate` onto ``CandidateEffect``.

Forward selection (``auto``): diagnose, add the best candidate while it is strong (ΔBIC > 10,
likelihood-ratio p < 1e-3; inside a group the tie-break of :mod:`mows.lab.diagnose` picks),
refit, repeat. Every step is recorded with χ²/dof, BIC and the leave-one-sweep-out
cross-validated rms error.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.lab import diagnose as diagnosis_module
from mows.lab.effects import catalog, resolve
from mows.lab.model import FrequencyModel
from mows.lab.table import MeasurementTable, load_table

MAX_AUTO_STEPS = 6


@dataclasses.dataclass
class HistoryStep:
    effects: list
    chi2_dof: float
    bic: float
    cv_rms_hz: float
    fit: object

    def to_dict(self) -> dict:
        return {"effects": self.effects, "chi2_dof": self.chi2_dof, "bic": self.bic,
                "cv_rms": None if not math.isfinite(self.cv_rms_hz) else self.cv_rms_hz}  # Hz (issue's key)


def history_step(fit, cross_validate: bool = True) -> HistoryStep:
    cv = fit.cross_validate() if cross_validate else math.nan
    return HistoryStep(fit.model.effect_names, fit.chi2_dof, fit.bic, cv, fit)


@dataclasses.dataclass
class LabReport:
    """The lab's answer for one table (fields map onto mows_msgs/ModelReport)."""

    model: str
    effects: list
    n: int
    chi2_dof: float
    bic: float
    cv_rms_hz: float
    verdict: str
    structure: str
    candidates: list
    groups: list
    history: list
    untestable: dict
    notes: list
    base: object
    fit: object
    diagnosis: object

    def to_dict(self) -> dict:
        """The JSON form (docs/model_lab.md): base, candidates, groups, history, verdict, structure…"""
        return {
            "base": {"chi2_dof": self.base.chi2_dof, "n": self.base.n, "bic": self.base.bic},
            "model": self.model,
            "effects": self.effects,
            "final": {"chi2_dof": self.chi2_dof, "bic": self.bic, "cv_rms_hz": _json_number(self.cv_rms_hz),
                      "parameters": {name: {"value": v, "std": s, "unit": u}
                                     for name, v, s, u in self.fit.parameters()}},
            "candidates": [c.to_dict() for c in self.candidates],
            "groups": [g.to_dict() for g in self.groups],
            "history": [h.to_dict() for h in self.history],
            "verdict": self.verdict,
            "verdict_explanation": self.diagnosis.explanation,
            "structure": self.diagnosis.structure.to_dict(),
            "untestable": self.untestable,
            "notes": self.notes,
        }


def _json_number(value):
    return value if math.isfinite(value) else None


def analyse(table, probe, effects=None, auto: bool = False, plugins=(), rank: bool = True,
            cross_validate: bool = True) -> LabReport:
    """Fit the published model plus ``effects`` (names) to ``table`` and diagnose what is missing.

    Parameters
    ----------
    table : a :class:`MeasurementTable`, a CSV path or a bag (see :func:`load_table`).
    probe : :class:`mows.probe.Probe`.
    effects : effect names added one by one to the base model (each a step of the history).
    auto : then add candidates forward while the evidence is strong.
    plugins : plugin files or entry-point names whose effects join the catalog.
    rank : test the catalog's candidates (``False``: fit and residual structure only).
    cross_validate : compute the leave-one-sweep-out error of every step.
    """
    table = table if isinstance(table, MeasurementTable) else load_table(table)
    available = catalog(plugins)
    fit = FrequencyModel(probe).fit(table)
    base = fit
    history = [history_step(fit, cross_validate)]
    for effect in resolve(list(effects or ()), available):
        fit = (fit.model + effect).fit(table, start=np.concatenate([fit.values[1:], np.zeros(len(effect.parameters))]))
        history.append(history_step(fit, cross_validate))
    pool = list(available.values()) if rank else []
    found = diagnosis_module.diagnose(fit, pool, probe)
    for _ in range(MAX_AUTO_STEPS if auto else 0):
        if found.best is None or not found.best.strong:
            break
        fit = found.best.fit
        history.append(history_step(fit, cross_validate))
        found = diagnosis_module.diagnose(fit, pool, probe)
    if not rank:
        found.explanation += " (Candidate effects were not tested: run `mows lab diagnose`.)"
    return LabReport(fit.model.name, fit.model.effect_names, fit.n, fit.chi2_dof, fit.bic, history[-1].cv_rms_hz,
                     found.verdict, found.structure.summary, found.candidates, found.groups, history,
                     found.untestable, list(table.notes), base, fit, found)
