"""Is a candidate the missing effect? One judgement for the search and the verdict.

A strong candidate (ΔBIC > 10 against the residual's own scatter, at values physics allows:
:mod:`mows.lab.diagnosis.candidates`, :mod:`mows.lab.diagnosis.plausibility`) is missing when:

- it **generalises**: its fit predicts the held-out configurations (whole sweeps, current steps,
  temperature spans) better than the present fit by more than the tie margin
  (:func:`mows.lab.diagnosis.candidates.cv_gain`);
- held at physics, that is all: known physics has no parameter to absorb another effect's
  signal;
- free, it **explains** at least half of the excess χ² − dof; a generic correction must leave a
  residual at noise (it stands for several causes, and where structure remains it takes a share
  of physics it is not); and where structure remains, it keeps strong evidence **beside what
  lies outside the catalog**: the terms the discovery finds (:func:`stand_ins`), held as
  additive terms with free strengths. Physics outside the catalog has a catalog effect take
  whatever share of its signal that effect's signature reaches (a tilted plane for the mean of a
  moment falling with temperature: the in-plane field shrinks as the cosine of the tilt); beside
  the stand-ins that share is gone, while an effect that is really there keeps its own.
"""

from __future__ import annotations

import math
import weakref

import numpy as np

from mows.lab.data.probe_rows import ProbeSet
from mows.lab.diagnosis.candidates import (
    STRONG_DELTA_BIC,
    TIE_DELTA_BIC,
    Candidate,
    closes_the_gap,
    cv_gain,
    explains_excess,
)
from mows.lab.diagnosis.discovery import Discovery, discover
from mows.lab.diagnosis.projections import cosine_within, orthonormal_basis, project_out, unit_columns
from mows.lab.model.effects import Effect
from mows.lab.model.least_squares import FitResult

SAME_SIGNATURE = 0.95  # a discovered term this close to a candidate's signature is the candidate's own
MAX_STAND_INS = 6  # the strongest discovered terms that stand in for physics outside the catalog (a sparse answer)


def is_missing(fit: FitResult, candidate: Candidate, probes: ProbeSet) -> bool:
    """``candidate`` is the effect ``fit``'s model is missing (module docstring)."""
    form = candidate.chosen
    if not candidate.strong or form.fit is None or cv_gain(fit, form.fit) <= TIE_DELTA_BIC:
        return False
    if form.fixed:
        return True
    if not explains_excess(fit, form):
        return False
    if closes_the_gap(form):
        return True
    return not candidate.effect.generic and beside_discovery(fit, candidate, probes)


def beside_discovery(fit: FitResult, candidate: Candidate, probes: ProbeSet) -> bool:
    """``candidate`` keeps strong evidence beside the terms the residual follows beyond the
    catalog (:func:`stand_ins`; module docstring). The stand-ins enter linearly, so each model's
    χ² beside them is one Gauss–Newton step from its own fit (``fit`` and the candidate's), with
    no refit; judged as :func:`mows.lab.diagnosis.candidates.quasi_gain` judges."""
    terms_in = stand_ins(fit, candidate, probes)
    with_candidate = candidate.chosen.fit
    if not terms_in or with_candidate is None:
        return True
    terms = np.column_stack([fit.extension_columns(e) for e in terms_in])  # the same at any point: additive

    def beside(model_fit: FitResult) -> tuple[float, int]:
        directions = orthonormal_basis(unit_columns(np.column_stack([model_fit.jacobian, terms])))
        left = project_out(model_fit.weighted_residual[:, None], directions)[:, 0]
        return float(left @ left), model_fit.n - directions.shape[1]

    without, _ = beside(fit)
    within, dof = beside(with_candidate)
    phi = max(1.0, within / max(dof, 1))
    return (without - within) / phi - len(candidate.effect.parameters) * math.log(fit.n) > STRONG_DELTA_BIC


def stand_ins(fit: FitResult, candidate: Candidate, probes: ProbeSet) -> list[Effect]:
    """The terms the residual follows beyond the catalog that ``candidate`` does not make itself,
    the strongest ``MAX_STAND_INS``: found with it in the model (what it leaves) and without it
    (what it may take a share of), each whose signature at ``fit`` lies outside the candidate's
    own (cos < ``SAME_SIGNATURE``: a temperature term is the thermal drift, not a stand-in for
    something else)."""
    assert candidate.chosen.fit is not None  # a strong form is refitted
    model_basis = orthonormal_basis(unit_columns(fit.jacobian))
    found: list[Effect] = []
    for model_fit in (candidate.chosen.fit, fit):
        for effect in _discovered(model_fit, probes).stand_ins:
            column = project_out(fit.extension_columns(effect), model_basis)[:, 0]
            outside = cosine_within(column, candidate.signature.basis) < SAME_SIGNATURE
            if outside and effect.name not in {e.name for e in found}:
                found.append(effect)
    return found[:MAX_STAND_INS]


# fit → what the discovery finds beside it (every candidate of a step asks of the same fit)
_DISCOVERED: weakref.WeakKeyDictionary[FitResult, Discovery] = weakref.WeakKeyDictionary()


def _discovered(fit: FitResult, probes: ProbeSet) -> Discovery:
    if fit not in _DISCOVERED:
        _DISCOVERED[fit] = discover(fit, probes, plugins=False)
    return _DISCOVERED[fit]
