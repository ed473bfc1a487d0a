"""One call from a table to a verdict: fit, diagnose, add effects, error history (the live API).

:func:`analyse` is what the mapper node calls after every sweep; :class:`LabReport` maps onto
``mows_msgs/ModelReport`` (model, effects, n, chi2_dof, bic, cv_rms_hz, verdict, structure,
candidates) and each :class:`mows.lab.diagnose.Candidate` onto ``CandidateEffect``.

Model selection (``auto``), stepwise by BIC with both forms of every effect (docs/model_lab.md):

1. **Forward step**: add the best strong candidate (ΔBIC > 10, p < 1e-3; inside a group the
   tie-break of :mod:`mows.lab.diagnose` picks) in its better form. An effect whose size
   follows from known constants (a physical value, e.g. a strength of 1) is tested both held at
   that value (no new parameter: ΔBIC = Δχ²) and free (ΔBIC = Δχ² − k·ln n). Known physics
   goes first: a strong candidate whose better form holds it at its physical value is added
   before free ones, because a free parameter can absorb the signal of a missing effect (a
   4-parameter curvature soaks up an amplitude and a deflection effect) and a fixed one cannot.
   With no strong candidate left, an effect is still added at physics when the data cannot
   reject it although they would see it if nothing absorbed it
   (:attr:`mows.lab.diagnose.Form.kept_physics`: a free tilt absorbs the amplitude's weakening
   of the pendulum spring, and reads the tilt 1 % low without it).
2. **Revisit** after every forward step: for each effect of the model, refit without it, rank
   every effect against that reduced model (the removed one in its other form included), and
   consider the reduced model, each refitted replacement, and — for a free effect with a
   physical value — the effect held at physics plus one refitted candidate; what a move adds
   must itself be positive evidence (ΔBIC > 2 on the model it joins). The best of these that
   the guard accepts replaces the model; repeat until none does. An effect added early
   whose free parameter was absorbing another effect (a strength of 0.92 soaking up the
   amplitude's weakening of the gradient springs) is thus put back at its physical value, or
   dropped, once the other effect is in.

Guard against over-fitting: the model grows only by forward steps, on strong evidence (or by
known physics, which adds no parameter and may cost at most ΔBIC 2); every revisit move lowers
the BIC — a move to fewer free parameters by any amount, to as many by more than 2 (positive
evidence: degenerate effects keep the tie-break's choice) — and the only move to more free
parameters is freeing an effect held at physics, on strong evidence. The revisit thus never
comes back to a model and ends; at most 6 forward steps. Every step is recorded with its
change, χ²/dof, BIC and the leave-one-sweep-out cross-validated rms error.

Every effect of the final model with a physical value gets a consistency check: its free fit
with the rest of the model (value ± σ; for one held at physics, a refit with it set free); a
physical value more than 3σ from it is reported in the notes.
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
MAX_REVISIT_MOVES = 6       # per forward step; each move lowers the BIC, so this is only a bound
CHECK_SIGMAS = 3.0          # a physical value further than this from its free fit is noted
NONLINEAR_MARGIN = 2.0      # a refit may gain up to this × the score statistic (the linearised gain)


@dataclasses.dataclass
class HistoryStep:
    """One model of the history: ``change`` says how it came from the previous one, ``check``
    holds the free fit [(name, value, std, unit)] of an effect added at physics."""

    effects: list
    chi2_dof: float
    bic: float
    cv_rms_hz: float
    fit: object
    change: str = "base model"
    check: list = dataclasses.field(default_factory=list)

    def to_dict(self) -> dict:
        return {"effects": self.effects, "change": self.change, "chi2_dof": self.chi2_dof, "bic": self.bic,
                "cv_rms": None if not math.isfinite(self.cv_rms_hz) else self.cv_rms_hz,  # Hz (issue's key)
                "free_fit": _parameters_dict(self.check)}


def history_step(fit, cross_validate: bool = True, change: str = "base model", check=()) -> HistoryStep:
    cv = fit.cross_validate() if cross_validate else math.nan
    return HistoryStep(fit.model.labels, fit.chi2_dof, fit.bic, cv, fit, change, list(check))


@dataclasses.dataclass
class PhysicsCheck:
    """An effect of the final model that has a physical value, against its free fit with the
    rest (for an effect held at physics, a refit with it set free)."""

    effect: str
    held: bool                # held at physics in the final model
    parameters: list          # [(name, value, std, unit)] of the free fit
    deviation_sigma: float    # largest |value − physical|/σ

    def to_dict(self) -> dict:
        return {"effect": self.effect, "held_at_physics": self.held, "parameters": _parameters_dict(self.parameters),
                "deviation_sigma": _json_number(self.deviation_sigma)}


def _parameters_dict(parameters) -> dict:
    return {name: {"value": v, "std": s, "unit": u} for name, v, s, u in parameters}


@dataclasses.dataclass
class LabReport:
    """The lab's answer for one table (fields map onto mows_msgs/ModelReport). ``effects`` are
    labels: ``name (at physics)`` for an effect held at its physical value."""

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
    physics_checks: list = dataclasses.field(default_factory=list)

    @property
    def effect_names(self) -> list:
        """The final model's effects by name, whatever their form."""
        return self.fit.model.effect_names

    def effect_parameter(self, name: str) -> tuple:
        """(value, σ) of ``effect.parameter`` in the final fit, or, for an effect held at
        physics, in its free fit (the consistency check)."""
        fitted = {n: (v, s) for n, v, s, _ in self.fit.parameters()}
        fitted.update({f"{c.effect}.{n}": (v, s) for c in self.physics_checks for n, v, s, _ in c.parameters})
        if name not in fitted:
            raise KeyError(f"no parameter {name} in the final model {self.model}")
        return fitted[name]

    def to_dict(self) -> dict:
        """The JSON form (docs/model_lab.md): base, candidates, groups, history, verdict, structure…"""
        return {
            "base": {"chi2_dof": self.base.chi2_dof, "n": self.base.n, "bic": self.base.bic},
            "model": self.model,
            "effects": self.effects,
            "final": {"chi2_dof": self.chi2_dof, "bic": self.bic, "cv_rms_hz": _json_number(self.cv_rms_hz),
                      "parameters": _parameters_dict(self.fit.parameters())},
            "physics_checks": [c.to_dict() for c in self.physics_checks],
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
    probe : :class:`mows.physics.probe.Probe`.
    effects : effect names added one by one to the base model (each a step of the history);
        ``name (at physics)`` adds the effect held at its physical value.
    auto : then select effects stepwise (module docstring).
    plugins : plugin files or entry-point names whose effects join the catalog.
    rank : test the catalog's candidates (``False``: fit and residual structure only).
    cross_validate : compute the leave-one-sweep-out error of every step.
    """
    table = load_table(table)
    available = catalog(plugins)
    fit = FrequencyModel(probe).fit(table)
    base = fit
    history = [history_step(fit, cross_validate)]
    for effect in resolve(list(effects or ()), available):
        fit = (fit.model + effect).fit(table, start=np.concatenate([fit.values[1:], np.zeros(len(effect.parameters))]))
        history.append(history_step(fit, cross_validate, f"add {effect.label}"))
    pool = list(available.values()) if rank else []
    found = diagnosis_module.diagnose(fit, pool, probe)
    for _ in range(MAX_AUTO_STEPS if auto else 0):
        step = _forward_step(found)
        if step is None:
            break
        change, fit, check = step
        history.append(history_step(fit, cross_validate, change, check))
        fit = _revisit(fit, pool, probe, history, cross_validate)
        found = diagnosis_module.diagnose(fit, pool, probe)
    if not rank:
        found.explanation += " (Candidate effects were not tested: run `mows lab diagnose`.)"
    checks = physics_checks(fit)
    notes = list(table.notes) + [_check_note(c) for c in checks if c.deviation_sigma > CHECK_SIGMAS]
    return LabReport(fit.model.name, fit.model.labels, fit.n, fit.chi2_dof, fit.bic, history[-1].cv_rms_hz,
                     found.verdict, found.structure.summary, found.candidates, found.groups, history,
                     found.untestable, notes, base, fit, found, checks)


def _forward_step(found):
    """(change, fit, check) of the next addition (module docstring), None when there is none.

    The best strong candidate in its better form, known physics first (a candidate held at
    its physical value has no parameter to absorb other effects with); else the best effect
    whose predicted signal the model's free parameters absorb but which the data cannot reject
    (:attr:`mows.lab.diagnose.Form.kept_physics`), held at physics.
    """
    strong = [c for c in found.candidates if c.strong]
    best = next((c for c in strong if c.chosen.fixed), strong[0] if strong else None)
    if best is not None:
        return f"add {best.label}", best.chosen.fit, best.parameters if best.chosen.fixed else ()
    for candidate in found.candidates:
        if candidate.physics is not None and candidate.physics.kept_physics:
            fit = candidate.physics.fit or (found.fit.model + candidate.effect.at_physics()).fit(
                found.fit.table, start=found.fit.values[1:])
            if found.fit.bic - fit.bic > -diagnosis_module.TIE_DELTA_BIC:  # the one-step estimate may be off
                return (f"add {candidate.label_of(candidate.physics)}: known physics the data cannot reject "
                        f"(ΔBIC {found.fit.bic - fit.bic:+.1f}, its predicted signal χ² "
                        f"{candidate.physics.signal_chi2:.3g} absorbed by free parameters)", fit, candidate.parameters)
    return None


def _revisit(fit, pool, probe, history, cross_validate):
    """Apply the best swap or removal while one lowers the BIC (module docstring)."""
    for _ in range(MAX_REVISIT_MOVES):
        move = _best_move(fit, pool, probe)
        if move is None:
            break
        change, fit = move
        history.append(history_step(fit, cross_validate, change))
    return fit


def _best_move(fit, pool, probe):
    """(change, fit) of the best alternative to ``fit`` (:func:`_alternatives`) that the guard
    accepts (:func:`_accepted`); None when there is none."""
    best = None
    for effect in fit.model.effects:
        for change, new, freed in _alternatives(fit, effect, pool, probe):
            if _accepted(fit, new, freed) and (best is None or new.bic < best[1].bic):
                best = (change, new)
    return best


def _accepted(old, new, freed: bool) -> bool:
    return old.bic - new.bic > _required_gain(old.k, new.k, freed)


def _required_gain(old_k: int, new_k: int, freed: bool) -> float:
    """The revisit's guard: the BIC a move from ``old_k`` to ``new_k`` free parameters must gain.
    Growth is the forward step's business (known physics first), so the only move that may add
    free parameters is freeing an effect held at physics (``freed``), and only on strong
    evidence (as a forward step). A move to as many free parameters needs positive evidence (so
    that effects the data cannot tell apart keep the tie-break's choice); one to fewer only has
    to lower the BIC."""
    if new_k > old_k:
        return diagnosis_module.STRONG_DELTA_BIC if freed else math.inf
    return diagnosis_module.TIE_DELTA_BIC if new_k == old_k else 0.0


def _alternatives(fit, effect, pool, probe) -> list:
    """[(change, fit, freed)] of the models that differ from ``fit`` in ``effect``:

    - without it;
    - with it replaced by one candidate in either form (itself in its other form included;
      ``freed`` marks an effect held at physics set free);
    - when it is free but has a physical value: held at that value *and* joined by one
      candidate, the move that undoes an absorption (a free strength of 0.92 standing in for
      itself at 1 plus a missing effect; neither form alone nor the missing effect alone on
      top of the free one lowers the BIC).
    """
    reduced = fit.model.without(effect).fit(fit.table, start=fit.values_without(effect))
    found = [(f"remove {effect.label}", reduced, False)]
    found += [(f"replace {effect.label} by {label}", new, freed)
              for label, new, freed in _replacements(fit, reduced, pool, probe, effect)]
    if effect.physical is not None and not effect.fixed:
        held = (reduced.model + effect.at_physics()).fit(fit.table, start=reduced.values[1:])
        found += [(f"replace {effect.label} by {held.model.labels[-1]} + {label}", new, freed)
                  for label, new, freed in _replacements(fit, held, pool, probe, effect)]
    return found


def _replacements(fit, start, pool, probe, replaced) -> list:
    """[(label, fit, freed)] of ``start`` plus one refitted candidate in either form (``freed``:
    the candidate is ``replaced``, held at physics in ``fit``, set free) that improves on
    ``start`` by positive evidence (ΔBIC > 2: a zero-parameter effect of no consequence does
    not ride along with a move). A form is refitted only if it could pass the guard: its
    linearised Δχ² is at most the score statistic, and a margin of ×2 covers the
    nonlinearity."""
    log_n = math.log(fit.n)

    def could_pass(effect, test, added) -> bool:
        if effect.name == replaced.name and (added == 0) == replaced.fixed:
            return False  # the replaced effect back in its own form: ``fit`` itself
        k = start.k + added
        needed = _required_gain(fit.k, k, replaced.fixed and effect.name == replaced.name)
        return start.chi2 - NONLINEAR_MARGIN * test.statistic + k * log_n < fit.bic - needed

    candidates, _ = diagnosis_module.rank_candidates(start, pool, probe, could_pass)
    # No passengers: what a move adds must itself be positive evidence on ``start``.
    return [(c.label_of(form), form.fit, replaced.fixed and c.name == replaced.name) for c in candidates
            for form in c.forms
            if form.fit is not None and start.bic - form.fit.bic > diagnosis_module.TIE_DELTA_BIC]


def physics_checks(fit) -> list:
    """For every effect of ``fit`` with a physical value: its free fit with the rest of the
    model (a refit for one held at physics), and how far the physical value lies from it."""
    checks = []
    for effect in fit.model.effects:
        if effect.physical is None:
            continue
        free = fit
        if effect.fixed:
            freed = fit.model.without(effect) + effect.free
            free = freed.fit(fit.table, start=np.concatenate([fit.values_without(effect), effect.physical]))
        parameters = free.effect_parameters(effect.name)
        checks.append(PhysicsCheck(effect.name, effect.fixed, parameters,
                                   diagnosis_module.physics_deviation(effect, parameters)))
    return checks


def _check_note(check: PhysicsCheck) -> str:
    values = ", ".join(f"{name} = {v:.4g} ± {s:.2g}" for name, v, s, _ in check.parameters)
    state = "is held at its physical value, but its free fit gives" if check.held else "is fitted free at"
    return (f"{check.effect} {state} {values}, {check.deviation_sigma:.1f}σ from its physical value: the "
            "physics as predicted misses something here, or the parameter absorbs another effect")
