"""Model selection: stepwise by BIC with both forms of every effect (docs/model_lab.md).

:func:`search` grows a fit from its diagnosis and records every step in the error history.

1. **Forward step**: add the best strong candidate (ΔBIC > 10, p < 1e-3; inside a group the
   tie-break of :mod:`mows.lab.diagnosis.indistinguishable` picks) in its better form. An effect whose size
   follows from known constants (a physical value, e.g. a strength of 1) is tested both held at
   that value (no new parameter: ΔBIC = Δχ²) and free (ΔBIC = Δχ² − k·ln n). Known physics
   goes first: a strong candidate whose better form holds it at its physical value is added
   before free ones, because a free parameter can absorb the signal of a missing effect (a
   4-parameter curvature soaks up an amplitude and a deflection effect) and a fixed one cannot.
   With no strong candidate left, an effect is still added at physics when the data cannot
   reject it although they would see it if nothing absorbed it
   (:attr:`mows.lab.diagnosis.candidates.Form.kept_physics`: a free tilt absorbs the amplitude's weakening
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

Every comparison of two models is the candidates' quasi-likelihood judgement (the verdict's):
Δχ²/φ − Δk·ln n with φ the scatter the better model leaves
(:func:`mows.lab.diagnosis.candidates.quasi_gain`); at noise it is the BIC difference. While the
residual stays far above noise no move that shaves a little off a huge χ² passes.

Guard against over-fitting: the model grows only by forward steps, on strong evidence (or by
known physics, which adds no parameter and may cost at most ΔBIC 2); every revisit move lowers
the BIC — a move to fewer free parameters by any amount, to as many by more than 2 (positive
evidence: degenerate effects keep the tie-break's choice) — and the only move to more free
parameters is freeing an effect held at physics, on strong evidence. The revisit thus never
comes back to a model and ends; at most 6 forward steps. Every step is recorded with its
change, χ²/dof, BIC and the cross-validated rms error (whole sweeps held out).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterable, Iterator, Sequence

import numpy as np

from mows.lab.data.probe_rows import ProbeSet
from mows.lab.diagnosis.candidates import (
    NONLINEAR_MARGIN,
    REJECTED_SIGMAS,
    STRONG_DELTA_BIC,
    TIE_DELTA_BIC,
    closes_the_gap,
    cv_gain,
    quasi_gain,
    rank_candidates,
)
from mows.lab.diagnosis.missing import is_missing
from mows.lab.diagnosis.physical_aliases import alias_statements
from mows.lab.diagnosis.plausibility import conflicts
from mows.lab.diagnosis.projections import Signature
from mows.lab.diagnosis.verdict import Diagnosis, completed, diagnose
from mows.lab.model.effects import Effect, untestable_reason
from mows.lab.model.least_squares import FitResult, FittedParameter, parameter_values, parameters_dict
from mows.records.json_numbers import finite_or_none

MAX_AUTO_STEPS = 6
MAX_REVISIT_MOVES = 6  # per forward step; each move lowers the BIC, so this is only a bound


@dataclasses.dataclass
class HistoryStep:
    """One model of the history: ``change`` says how it came from the previous one, ``check``
    holds the free fit of an effect added at physics."""

    effects: list[str]  # the model's labels
    chi2_dof: float
    bic: float
    cv_rms_hz: float
    fit: FitResult
    change: str = "base model"
    check: list[FittedParameter] = dataclasses.field(default_factory=list)
    cv_identifiable: bool = True  # False: a left-out sweep held the only information on a parameter

    @property
    def cv_text(self) -> str:
        """The cross-validated rms in mHz, or why there is none."""
        if not self.cv_identifiable:
            return "not identifiable from these sweeps"
        return f"{self.cv_rms_hz * 1e3:.4f}" if math.isfinite(self.cv_rms_hz) else "-"

    def to_dict(self) -> dict:
        return {
            "effects": self.effects,
            "change": self.change,
            "chi2_dof": self.chi2_dof,
            "bic": self.bic,
            "cv_rms": finite_or_none(self.cv_rms_hz),  # Hz
            "cv_identifiable": self.cv_identifiable,
            "free_fit": parameters_dict(self.check),
        }


def history_step(
    fit: FitResult, cross_validate: bool = True, change: str = "base model", check: Iterable[FittedParameter] = ()
) -> HistoryStep:
    cv = fit.cross_validate() if cross_validate else math.nan
    return HistoryStep(
        fit.model.labels,
        fit.chi2_dof,
        fit.bic,
        cv,
        fit,
        change,
        list(check),
        cv_identifiable=not (cross_validate and math.isnan(cv)),
    )


def search(
    found: Diagnosis,
    pool: Sequence[Effect],
    probes: ProbeSet,
    history: list[HistoryStep],
    cross_validate: bool = True,
    steps: int = MAX_AUTO_STEPS,
) -> Diagnosis:
    """The diagnosis of the selected model, starting from ``found`` (the diagnosis of the
    present fit, which may leave out what only a report reads): up to ``steps`` forward steps,
    each followed by the revisit, every model appended to ``history`` (module docstring)."""
    for _ in range(steps):
        step = _forward_step(found, probes)
        if step is None:
            # Only now may an effect held at physics be set free: nothing in the catalog is left
            # to explain the residual with the physics held.
            fit = _revisit(found.fit, pool, probes, history, cross_validate, freeing=True)
            if fit is found.fit:
                break
        else:
            change, fit, check = step
            history.append(history_step(fit, cross_validate, change, check))
            fit = _revisit(fit, pool, probes, history, cross_validate, freeing=False)
        found = diagnose(fit, pool, probes, for_report=False)
    if steps:
        found = prefer_physical(found, pool, probes, history, cross_validate)
    return completed(found, pool, probes)


def prefer_physical(
    found: Diagnosis, pool: Sequence[Effect], probes: ProbeSet, history: list[HistoryStep], cross_validate: bool = True
) -> Diagnosis:
    """The diagnosis after each generic correction of the model (``Effect.generic``: moment
    scale, field offset, spring drift, angle offset) is replaced by a physical effect that fits
    as well (BIC at most 2 worse, no more free parameters, free values inside their bounds),
    known physics held at its value first: a generic term stands for several causes, the
    physical alias names one (a moment scale of −0.85 % where a 15° amplitude predicts
    −0.86 %). Each replacement is a step of ``history`` that says why."""
    fit = found.fit
    for generic in [e for e in fit.model.effects if e.generic]:
        best: tuple[Effect, FitResult] | None = None
        for form, new in _physical_replacements(fit, generic, pool, probes):
            better = best is None or (form.fixed, -new.bic) > (best[0].fixed, -best[1].bic)
            if quasi_gain(fit, new) > -TIE_DELTA_BIC and better:
                best = (form, new)
        if best is None:
            continue
        form, new = best
        aliases = alias_statements(
            [generic.name, form.name],
            new,
            probes,
            {generic.name: parameter_values(fit.effect_parameters(generic.name))},
        )
        history.append(
            history_step(
                new,
                cross_validate,
                (
                    f"replace {generic.label} by {form.label}: they fit alike (ΔBIC {fit.bic - new.bic:+.1f}); "
                    f"{form.name} is physics{' of known size' if form.fixed else ''}, "
                    f"{generic.name} a generic correction" + "".join(f" ({alias})" for alias in aliases)
                ),
            )
        )
        fit = new
    return found if fit is found.fit else diagnose(fit, pool, probes, for_report=False)


def _physical_replacements(
    fit: FitResult, generic: Effect, pool: Sequence[Effect], probes: ProbeSet
) -> Iterator[tuple[Effect, FitResult]]:
    """(form, fit) of the model with ``generic`` replaced by each physical effect of ``pool``
    not in it: held at physics where it has a physical value, else free, with no more free
    parameters than ``generic`` and every free value inside its bounds."""
    reduced = fit.model.without(generic)
    start = fit.values_without(generic)
    for effect in pool:
        if effect.generic or effect.name in fit.model.effect_names or untestable_reason(effect, fit.table, probes):
            continue
        form = effect.at_physics() if effect.physical is not None else effect
        if len(form.parameters) > len(generic.parameters):
            continue
        new = (reduced + form).fit(fit.table, start=np.concatenate([start, form.off_values]))
        values = [p.value for p in new.effect_parameters(form.name)]
        inside = all(p.lower < v < p.upper for p, v in zip(form.parameters, values))
        if new.ok and inside and not conflicts(new, probes):
            yield form, new


def _forward_step(found: Diagnosis, probes: ProbeSet) -> tuple[str, FitResult, Sequence[FittedParameter]] | None:
    """(change, fit, check) of the next addition (module docstring), None when there is none.

    The best strong candidate in its better form that the judgement of
    :func:`mows.lab.diagnosis.missing.is_missing` takes (it generalises and, free, explains the
    structure rather than a share of physics outside the catalog), known physics first (a
    candidate held at its physical value has no parameter to absorb other effects with); else
    the best effect
    whose predicted signal the model's free parameters absorb but which the data cannot reject
    (:attr:`mows.lab.diagnosis.candidates.Form.kept_physics`), held at physics.
    """
    strong = [c for c in found.candidates if c.strong]
    for best in sorted(strong, key=lambda c: not c.chosen.fixed):  # known physics first, stably
        if is_missing(found.fit, best, probes):
            assert best.chosen.fit is not None  # a strong form is always refitted (candidates._candidate)
            return f"add {best.label}", best.chosen.fit, best.parameters if best.chosen.fixed else ()
    for candidate in found.candidates:
        if candidate.physics is not None and candidate.physics.kept_physics:
            fit = candidate.physics.fit or (found.fit.model + candidate.effect.at_physics()).fit(
                found.fit.table, start=found.fit.effect_values
            )
            acceptable = not conflicts(fit, probes) and cv_gain(found.fit, fit) > -TIE_DELTA_BIC
            if quasi_gain(found.fit, fit) > -TIE_DELTA_BIC and acceptable:  # the one-step estimate may be off
                return (
                    f"add {candidate.label_of(candidate.physics)}: known physics the data cannot reject "
                    f"(ΔBIC {found.fit.bic - fit.bic:+.1f}, its predicted signal χ² "
                    f"{candidate.physics.signal_chi2:.3g} absorbed by free parameters)",
                    fit,
                    candidate.parameters,
                )
    return None


def _revisit(
    fit: FitResult,
    pool: Sequence[Effect],
    probes: ProbeSet,
    history: list[HistoryStep],
    cross_validate: bool,
    freeing: bool,
) -> FitResult:
    """Apply the best swap or removal while one lowers the BIC (module docstring); ``freeing``:
    setting an effect held at physics free is one of the moves."""
    for _ in range(MAX_REVISIT_MOVES):
        move = _best_move(fit, pool, probes, freeing)
        if move is None:
            break
        change, fit = move
        history.append(history_step(fit, cross_validate, change))
    return fit


def _best_move(fit: FitResult, pool: Sequence[Effect], probes: ProbeSet, freeing: bool) -> tuple[str, FitResult] | None:
    """(change, fit) of the best alternative to ``fit`` (:func:`_alternatives`) that the guard
    accepts (:func:`_accepted`; a move that sets free an effect held at physics only when
    ``freeing``); None when there is none."""
    best: tuple[str, FitResult] | None = None
    for effect in fit.model.effects:
        for change, new, freed in _alternatives(fit, effect, pool, probes):
            if (
                (freeing or not freed)
                and _accepted(fit, new, freed, probes)
                and (best is None or new.bic < best[1].bic)
            ):
                best = (change, new)
    return best


def _accepted(old: FitResult, new: FitResult, freed: bool, probes: ProbeSet) -> bool:
    """The guard on a revisit move: the BIC gain :func:`_required_gain` asks, at values physics
    allows, and held-out rows predicted no worse (better, for a move that sets an effect free)."""
    if quasi_gain(old, new) <= _required_gain(old.k, new.k, freed) or conflicts(new, probes):
        return False
    brought = {e.name for e in new.model.effects if e.generic} - set(old.model.effect_names)
    if brought and not closes_the_gap(new):  # a generic correction must explain the data, however it comes in
        return False
    return new.k < old.k or cv_gain(old, new) > (TIE_DELTA_BIC if freed else -TIE_DELTA_BIC)


def _required_gain(old_k: int, new_k: int, freed: bool) -> float:
    """The revisit's guard: the BIC a move from ``old_k`` to ``new_k`` free parameters must gain.
    Growth is the forward step's business (known physics first), so the only move that may add
    free parameters is freeing an effect held at physics (``freed``), and only on strong
    evidence (as a forward step). A move to as many free parameters needs positive evidence (so
    that effects the data cannot tell apart keep the tie-break's choice); one to fewer only has
    to lower the BIC."""
    if new_k > old_k:
        return STRONG_DELTA_BIC if freed else math.inf
    return TIE_DELTA_BIC if new_k == old_k else 0.0


def _alternatives(
    fit: FitResult, effect: Effect, pool: Sequence[Effect], probes: ProbeSet
) -> list[tuple[str, FitResult, bool]]:
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
    found += [
        (f"replace {effect.label} by {label}", new, freed)
        for label, new, freed in _replacements(fit, reduced, pool, probes, effect)
    ]
    if effect.physical is not None and not effect.fixed:
        held = (reduced.model + effect.at_physics()).fit(fit.table, start=reduced.effect_values)
        found += [
            (f"replace {effect.label} by {held.model.labels[-1]} + {label}", new, freed)
            for label, new, freed in _replacements(fit, held, pool, probes, effect)
        ]
    return found


def _replacements(
    fit: FitResult, start: FitResult, pool: Sequence[Effect], probes: ProbeSet, replaced: Effect
) -> list[tuple[str, FitResult, bool]]:
    """[(label, fit, freed)] of ``start`` plus one refitted candidate in either form (``freed``:
    the candidate is ``replaced``, held at physics in ``fit``, set free) that improves on
    ``start`` by positive evidence (ΔBIC > 2: a zero-parameter effect of no consequence does
    not ride along with a move). A form is refitted only if it could pass the guard: its
    linearised Δχ² is at most the score statistic, and a margin of ×2 covers the
    nonlinearity."""
    log_n = math.log(fit.n)

    def could_pass(effect: Effect, test: Signature, added: int) -> bool:
        if effect.name == replaced.name and (added == 0) == replaced.fixed:
            return False  # the replaced effect back in its own form: ``fit`` itself
        k = start.k + added
        needed = _required_gain(fit.k, k, replaced.fixed and effect.name == replaced.name)
        return start.chi2 - NONLINEAR_MARGIN * test.statistic + k * log_n < fit.bic - needed

    candidates, _ = rank_candidates(start, pool, probes, could_pass)
    # No passengers: what a move adds must itself be positive evidence on ``start``; and a free
    # form pinned at a parameter bound is no minimum, only a fudge (a free damping blend of 100
    # ± 109, bound 100, once bought a nearby-coil table 3 in BIC).
    # An effect held at physics is set free only where the data reject its physical value.
    return [
        (c.label_of(form), form.fit, freed)
        for c in candidates
        for form in c.forms
        for freed in [replaced.fixed and c.name == replaced.name]
        if form.fit is not None
        and form.possible
        and quasi_gain(start, form.fit) > TIE_DELTA_BIC
        and (form.fixed or c.within_bounds)
        and (not freed or c.physics_deviation > REJECTED_SIGMAS)
    ]
