"""Candidate effects: each catalog effect tested as the explanation of a fit's residual.

Each testable effect's signature (its Jacobian columns at 0, projected orthogonally to the fit,
:mod:`mows.lab.diagnosis.projections`) gives a score test; the effect is then refitted with the model
(nonlinear least squares): ΔBIC = Δχ²/φ − k·ln n, p-value of the likelihood ratio
Δχ²/φ ~ χ²(k), parameters ± σ, where φ = max(1, the smallest χ²/dof the step reaches, with
or without any one candidate) is the residual's own scatter, one for every candidate of the step
(quasi-likelihood, :func:`dispersion`; φ = 1 once the residual is noise). An effect whose size
follows from known constants (``Effect.physical``) is also refitted held at that value, with no
new parameter (ΔBIC = Δχ²/φ, p of two simple hypotheses, :func:`_physics_form`); the candidate
stands for the better form, and keeps the free fit's parameters as a check.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Iterable

import numpy as np
import scipy.stats

from mows.lab import progress
from mows.lab.data.probe_rows import ProbeSet
from mows.lab.diagnosis import plausibility
from mows.lab.diagnosis.plausibility import Conflict
from mows.lab.diagnosis.projections import Signature, orthonormal_basis, project_out, signature
from mows.lab.diagnosis.residual_structure import GOODNESS_ALPHA
from mows.lab.model.effects import Effect, untestable_reason
from mows.lab.model.least_squares import FitResult, FittedParameter, parameters_dict
from mows.records.json_numbers import finite_or_none

TIE_DELTA_BIC = 2.0
STRONG_DELTA_BIC = 10.0
STRONG_P = 1e-3
REFIT_P = 0.05
NONLINEAR_MARGIN = 2.0  # a refit may gain up to this × the score statistic (the linearised gain)
REJECTED_SIGMAS = 3.0  # a free fit this far from an effect's physical value rejects that value
EXPLAINED_FRACTION = 0.5  # of the excess χ² − dof: a free effect that explains less only shaves the structure
ABSORBED = "no signature in this table that the current model cannot already absorb"

# worth_refit(effect, signature, free parameters the form adds): refit rather than take the one-step estimate
WorthRefit = Callable[[Effect, Signature, int], bool]


# --- candidates -----------------------------------------------------------------------------
@dataclasses.dataclass
class Form:
    """One way of adding an effect to the current fit: its parameters free (ΔBIC = Δχ² − k·ln n,
    p of the likelihood ratio Δχ² ~ χ²(k)), or held at their physical values (``fixed``: no new
    parameter, ΔBIC = Δχ², p of the simple-versus-simple likelihood ratio, see
    :func:`_physics_form`). ``fit`` is the nonlinear refit, None for the one-step estimate."""

    fixed: bool
    delta_bic: float
    p_value: float
    chi2_after: float
    dof_after: int
    fit: FitResult | None = None
    signal_chi2: float = math.nan  # at physics: Σ(predicted signal/σ)² beyond what f00 absorbs
    dispersion: float = 1.0  # φ the evidence was scaled by (:func:`dispersion`)
    gain_chi2: float = math.nan  # Δχ² before the scaling by φ
    added: int = 0  # free parameters the form adds (k)
    rank: int = 0  # of the effect's projected signature
    shift_norm: float = 0.0  # at physics: ‖weighted shift of the residual‖ before the scaling
    conflicts: tuple[Conflict, ...] = ()  # what the form's fit claims that physics does not allow

    @property
    def possible(self) -> bool:
        """The form's fit is physics (:mod:`mows.lab.diagnosis.plausibility`)."""
        return not self.conflicts

    def at_dispersion(self, phi: float, n: int) -> Form:
        """This form judged against the scatter φ: ΔBIC = Δχ²/φ − k·ln n and its p-value (free:
        Δχ²/φ ~ χ²(rank); at physics: the simple-versus-simple test of :func:`_physics_form`)."""
        gain = self.gain_chi2 / phi
        if self.fixed:
            size = self.shift_norm / math.sqrt(phi)
            p = float(scipy.stats.norm.sf((gain + size**2) / (2 * size))) if size > 0 else 1.0
            return dataclasses.replace(self, delta_bic=gain, p_value=p, dispersion=phi)
        p = float(scipy.stats.chi2.sf(max(gain, 0.0), self.rank))
        return dataclasses.replace(self, delta_bic=gain - self.added * math.log(n), p_value=p, dispersion=phi)

    @property
    def chi2_dof_after(self) -> float:
        return self.chi2_after / max(self.dof_after, 1)

    @property
    def kept_physics(self) -> bool:
        """Known physics the data cannot reject: held at physics, its predicted signal would be
        strong evidence if no free parameter absorbed it (against the residual's scatter, φ),
        and adding it costs less than the tie margin of BIC (how :mod:`mows.lab.report.lab_report` uses it)."""
        return self.fixed and self.signal_chi2 / self.dispersion > STRONG_DELTA_BIC and self.delta_bic > -TIE_DELTA_BIC

    def to_dict(self) -> dict:
        return {
            "delta_bic": finite_or_none(self.delta_bic),
            "p_value": finite_or_none(self.p_value),
            "chi2_dof_after": finite_or_none(self.chi2_dof_after),
            "would_need": [c.to_dict() for c in self.conflicts],
        }


@dataclasses.dataclass
class Candidate:
    """One effect tested against the current fit (fields map onto mows_msgs/CandidateEffect).

    Effects with a physical value are tested in both forms (``free`` and ``physics``); the
    candidate stands for the better of the two by BIC (:attr:`form`; the fewer parameters on a
    tie): ``delta_bic``, ``p_value`` and ``chi2_dof_after`` are that form's (:attr:`chosen`).
    ``parameters`` are always the free fit's, so that a candidate held at physics still shows
    how far its physical value lies from what the data say alone (:attr:`physics_deviation`).
    """

    effect: Effect
    free: Form
    physics: Form | None
    score_p_value: float
    parameters: list[FittedParameter]  # of the free form
    within_bounds: bool
    signature: Signature
    group: int = 0

    @property
    def name(self) -> str:
        return self.effect.name

    @property
    def chosen(self) -> Form:
        """The form the candidate stands for: held at physics unless the data reject the
        physical value (the free fit lies more than ``REJECTED_SIGMAS`` of its σ from it) and
        the free form is better by ΔBIC; a form physics allows over one it does not."""
        if self.physics is None:
            return self.free
        if self.physics.possible != self.free.possible:
            return self.physics if self.physics.possible else self.free
        rejected = self.physics_deviation > REJECTED_SIGMAS
        return self.free if rejected and self.free.delta_bic > self.physics.delta_bic else self.physics

    @property
    def forms(self) -> list[Form]:
        return [self.free] + ([self.physics] if self.physics is not None else [])

    def at_dispersion(self, phi: float, n: int) -> Candidate:
        """Both forms judged against the step's scatter φ (:func:`dispersion`)."""
        physics = None if self.physics is None else self.physics.at_dispersion(phi, n)
        return dataclasses.replace(self, free=self.free.at_dispersion(phi, n), physics=physics)

    @property
    def form(self) -> str:
        return "at physics" if self.chosen.fixed else "free"

    def label_of(self, form: Form) -> str:
        return self.effect.at_physics().label if form.fixed else self.name

    @property
    def label(self) -> str:
        return self.label_of(self.chosen)

    @property
    def delta_bic(self) -> float:
        return self.chosen.delta_bic

    @property
    def p_value(self) -> float:
        return self.chosen.p_value

    @property
    def chi2_dof_after(self) -> float:
        return self.chosen.chi2_dof_after

    @property
    def physics_deviation(self) -> float:
        """Largest |free value − physical value|/σ over the parameters (NaN without a physical value)."""
        return physics_deviation(self.effect, self.parameters)

    @property
    def strong(self) -> bool:
        """Strong evidence, at values physics allows."""
        return self.delta_bic > STRONG_DELTA_BIC and self.p_value < STRONG_P and self.chosen.possible

    @property
    def would_need(self) -> str:
        """What the effect would need, where physics does not allow it ("" where it does): the
        finding when the data ask for it strongly."""
        return "; ".join(c.text for c in self.chosen.conflicts)

    def to_dict(self) -> dict:
        return {
            "effect": self.name,
            "form": self.form,
            "label": self.label,
            "delta_bic": finite_or_none(self.delta_bic),
            "p_value": finite_or_none(self.p_value),
            "score_p_value": finite_or_none(self.score_p_value),
            "chi2_dof_after": finite_or_none(self.chi2_dof_after),
            "parameters": parameters_dict(self.parameters),
            "free": self.free.to_dict(),
            "at_physics": None if self.physics is None else self.physics.to_dict(),
            "physics_deviation_sigma": finite_or_none(self.physics_deviation),
            "within_bounds": self.within_bounds,
            "would_need": self.would_need,
            "group": self.group,
            "explanation": self.effect.explanation,
        }


def physics_deviation(effect: Effect, parameters: list[FittedParameter]) -> float:
    """Largest |value − physical value|/σ of an effect's fitted ``parameters``; NaN when the
    effect has no physical value."""
    if effect.physical is None or not parameters:
        return math.nan
    return max(
        abs(p.value - physical) / p.std if p.std > 0 else math.inf for p, physical in zip(parameters, effect.physical)
    )


def dispersion(fit: FitResult, candidates: Iterable[Candidate]) -> float:
    """φ = max(1, χ²/dof) of the best model this step can reach (``fit`` or ``fit`` with any one
    candidate form): the residual's own scatter in units of the stated uncertainties
    (quasi-likelihood, as QAIC takes φ from the fullest model). While the residual stays far
    above noise, a raw-χ² BIC rewards any parameter that shaves a little off a huge χ²; judged
    against the scatter that no candidate removes, Δχ²/φ, only an effect that explains the
    structure (and so brings φ to ≈ 1) gains real evidence. One φ for every candidate of a step,
    so that candidates are ranked by their Δχ², not by their own scatter; a form at values
    physics does not allow reaches nothing. φ = 1 once the residual is noise."""
    after = [f.chi2_after / max(f.dof_after, 1) for c in candidates for f in c.forms if f.possible]
    return max(1.0, min([fit.chi2_dof, *after]))


def quasi_gain(old: FitResult, new: FitResult) -> float:
    """The evidence for ``new`` over ``old`` (two fits of one table) as the candidates judge it:
    Δχ²/φ − Δk·ln n, with φ = max(1, the smaller χ²/dof of the two) the scatter the better one
    leaves (:func:`dispersion`). With the residual at noise this is the BIC difference; far
    above it, a move that shaves a little off a huge χ² gains nothing."""
    phi = max(1.0, min(old.chi2_dof, new.chi2_dof))
    return (old.chi2 - new.chi2) / phi - (new.k - old.k) * math.log(new.n)


def explains_excess(fit: FitResult, form: Form) -> bool:
    """``form`` accounts for at least ``EXPLAINED_FRACTION`` of ``fit``'s excess χ² − dof. A free
    effect that explains less of a residual far above noise fits some of the structure of
    physics it is not: a spring drift takes the mean of a moment falling with temperature."""
    return fit.chi2 - form.chi2_after >= EXPLAINED_FRACTION * (fit.chi2 - fit.dof)


def closes_the_gap(form: Form | FitResult) -> bool:
    """With ``form`` (or in a fit) the residual is consistent with noise (χ² p ≥ the verdict's GOODNESS_ALPHA).
    A generic correction (``Effect.generic``) stands for several causes; it is credible only
    where it explains the data: where structure remains, some other physics is at work and the
    correction would take a share of its signal (a moment scale of −0.4 %, the mean of a moment
    falling with temperature, where the calibration is right)."""
    chi2, dof = (form.chi2_after, form.dof_after) if isinstance(form, Form) else (form.chi2, form.dof)
    return float(scipy.stats.chi2.sf(chi2, max(dof, 1))) >= GOODNESS_ALPHA


def cv_gain(old: FitResult, new: FitResult) -> float:
    """The held-out χ² ``new`` saves over ``old`` (:attr:`FitResult.held_out_chi2`: each fold
    predicted by the fit without it), scaled by the scatter as :func:`quasi_gain` scales the
    in-sample gain. An effect that describes physics predicts configurations the fit did not
    see; one that only absorbs the structure of a few of them does not."""
    phi = max(1.0, min(old.chi2_dof, new.chi2_dof))
    return (old.held_out_chi2 - new.held_out_chi2) / phi


def rank_candidates(
    fit: FitResult, effects: Iterable[Effect], probes: ProbeSet, worth_refit: WorthRefit | None = None
) -> tuple[list[Candidate], dict[str, str]]:
    """(candidates best first, {effect: why it cannot be tested}) for the ``effects`` not yet in
    ``fit``'s model: score test on the projected signature, then each form's refit where
    ``worth_refit(effect, signature, added)`` (``added``: the free parameters the form adds;
    default: :func:`could_be_evidence`), else the one-step estimate."""
    residual = fit.weighted_residual
    model_basis = orthonormal_basis(fit.jacobian)
    tests: list[tuple[Effect, Signature]] = []
    untestable: dict[str, str] = {}
    effects = [effect for effect in effects if effect.name not in fit.model.effect_names]
    for done, effect in enumerate(effects):
        progress.stage("ranking candidate effects", done, len(effects))
        reason = untestable_reason(effect, fit.table, probes)
        test = None if reason else signature(fit.extension_columns(effect), model_basis, residual)
        if test is not None and not test.rank:
            reason = ABSORBED
        if reason:
            untestable[effect.name] = reason
            continue
        assert test is not None  # there was a test unless there was a reason not to test
        tests.append((effect, test))
    worth_refit = worth_refit or could_be_evidence(fit, [test for _, test in tests])
    candidates = [
        _candidate(fit, effect, test, functools.partial(worth_refit, effect, test), probes) for effect, test in tests
    ]
    phi = dispersion(fit, candidates)
    candidates = [c.at_dispersion(phi, fit.n) for c in candidates]
    candidates.sort(key=lambda c: -c.delta_bic)
    return candidates, untestable


def could_be_evidence(fit: FitResult, tests: list[Signature]) -> WorthRefit:
    """The default refit rule: refit a form only where it could be positive evidence (ΔBIC > 2)
    against the step's scatter. A refit gains at most ``NONLINEAR_MARGIN`` × the score statistic
    (the linearised Δχ²), and the scatter φ no form can bring below (χ² less the largest such
    gain, per degree of freedom) scales it. Far above noise, where every score test is
    significant, this spares the refits of effects that could only shave the residual."""
    largest = max((test.statistic for test in tests), default=0.0)
    floor = max(1.0, (fit.chi2 - NONLINEAR_MARGIN * largest) / max(fit.dof, 1))
    log_n = math.log(fit.n)

    def worth(effect: Effect, test: Signature, added: int) -> bool:
        return test.p_value < REFIT_P and NONLINEAR_MARGIN * test.statistic / floor - added * log_n > TIE_DELTA_BIC

    return worth


def _candidate(
    fit: FitResult, effect: Effect, test: Signature, refit: Callable[[int], bool], probes: ProbeSet
) -> Candidate:
    """Refit the model with ``effect`` in each form where ``refit(added free parameters)``, or
    take the one-step (linearised) refit along the projected signature. A Δχ² above the strong
    threshold needs a score statistic above it too (the score is the largest Δχ² of the
    linearised problem), so with the default rule no strong form is left to the one-step
    estimate. Each refitted form is checked against physics (:func:`plausibility.conflicts`)."""
    free, parameters = _free_form(fit, effect, test, refit(len(effect.parameters)))
    free = dataclasses.replace(
        free,
        conflicts=tuple(
            plausibility.conflicts(free.fit, probes)
            if free.fit is not None
            else plausibility.effect_conflicts(effect, parameters, probes, fit.table)
        ),
    )
    physics = None if effect.physical is None else _physics_form(fit, effect, test, refit(0))
    if physics is not None and physics.fit is not None:
        physics = dataclasses.replace(physics, conflicts=tuple(plausibility.conflicts(physics.fit, probes)))
    inside = all(
        p.lower + 1e-6 * (p.upper - p.lower) < fitted.value < p.upper - 1e-6 * (p.upper - p.lower)
        for p, fitted in zip(effect.parameters, parameters)
    )
    return Candidate(effect, free, physics, test.p_value, parameters, inside, test)


def _free_form(fit: FitResult, effect: Effect, test: Signature, refit: bool) -> tuple[Form, list[FittedParameter]]:
    """(Form, parameters) of ``effect`` added with its parameters free."""
    k = len(effect.parameters)
    if refit:
        after = (fit.model + effect).fit(fit.table, start=np.concatenate([fit.effect_values, effect.off_values]))
        chi2_after, dof_after, parameters = after.chi2, after.dof, after.effect_parameters(effect.name)
    else:
        after = None
        step = -np.linalg.pinv(test.projected) @ fit.weighted_residual
        std = np.sqrt(np.clip(np.diag(np.linalg.pinv(test.projected.T @ test.projected)), 0, None))
        chi2_after, dof_after = fit.chi2 - test.statistic, fit.dof - test.rank
        parameters = [
            FittedParameter(p.name, p.off + float(v), float(e), p.unit) for p, v, e in zip(effect.parameters, step, std)
        ]
    raw = Form(False, math.nan, math.nan, chi2_after, dof_after, after, gain_chi2=fit.chi2 - chi2_after, added=k)
    return dataclasses.replace(raw, rank=test.rank).at_dispersion(1.0, fit.n), parameters


def _physics_form(fit: FitResult, effect: Effect, test: Signature, refit: bool) -> Form:
    """``effect`` added at its physical values: no new parameter, ΔBIC = Δχ².

    The p-value is that of the likelihood ratio of two simple hypotheses (Neyman–Pearson): the
    effect adds the known signal s (weighted, after the current model's parameters have
    absorbed what they can: s = r_after − r, S = ‖s‖), and under the current model
    Δχ² = −2·r·s − S² is Gaussian with mean −S² and variance 4S², so p = P(Δχ² ≥ observed) =
    Q((Δχ² + S²)/(2S)). A form whose signal is below the noise cannot reach a small p.
    ``signal_chi2`` is the predicted signal's size before the model's parameters absorb it
    (only the constant that f00 takes is removed), linearised.
    """
    residual = fit.weighted_residual
    assert test.columns is not None  # rank_candidates' signatures keep their columns
    predicted = test.columns @ np.asarray(effect.physical, float)
    signal = project_out(predicted[:, None], orthonormal_basis(fit.jacobian[:, :1]))
    if refit:
        after = (fit.model + effect.at_physics()).fit(fit.table, start=fit.effect_values)
        shift, chi2_after, dof_after = after.weighted_residual - residual, after.chi2, after.dof
    else:
        after = None
        shift = test.projected @ np.asarray(effect.physical, float)
        chi2_after, dof_after = float(np.sum((residual + shift) ** 2)), fit.dof
    raw = Form(True, math.nan, math.nan, chi2_after, dof_after, after, float(np.sum(signal**2)))
    raw = dataclasses.replace(raw, gain_chi2=fit.chi2 - chi2_after, shift_norm=float(np.linalg.norm(shift)))
    return raw.at_dispersion(1.0, fit.n)
