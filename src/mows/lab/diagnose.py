"""Where the model fails and which effect is missing: residual structure, candidates, verdict.

Everything is measured against what the current fit can already absorb. With J the Jacobian
of the weighted residuals r = (f − model)/σ over the current model's free parameters, every
test direction (a harmonic of θ0, a covariate, a candidate effect's parameters at 0) is first
projected orthogonally to J: P⊥ = I − Q·Qᵀ, Q an orthonormal basis of J.

- **Residual structure**: harmonics k = 0…4 of θ0 (columns cos kθ0/σ, sin kθ0/σ) and each
  covariate (column c/σ), projected; score statistic S = ‖Uᵀr‖² (U an orthonormal basis of the
  projected columns) ~ χ²(rank) under the model; amplitudes from the projected least squares.
  Significant means p < 0.005 after Bonferroni over all these tests.
- **Candidates**: each testable effect's signature (its Jacobian columns at 0, projected) gives a
  score test; the effect is then refitted with the model (nonlinear least squares):
  ΔBIC = Δχ² − k·ln n, p-value of the likelihood ratio Δχ² ~ χ²(k), parameters ± σ. An effect
  whose size follows from known constants (``Effect.physical``) is also refitted held at that
  value, with no new parameter (ΔBIC = Δχ², p of two simple hypotheses, :func:`_physics_form`);
  the candidate stands for the better form, and keeps the free fit's parameters as a check.
- **Groups**: two significant candidates (p < 0.01) cannot be told apart by this data when each
  one's fitted signal, v_A = P_A⊥·r (the residual's projection on A's projected signature),
  lies within the other's signature space: cos(v_A, span B⊥) ≥ 0.95 both ways. Groups are the
  connected sets of such pairs.
- **Separating measurements**: the group's signatures and fitted signals (the fitted linear
  coefficients, extended) are evaluated on the table joined with a what-if variant of it (more
  angles, half the amplitude, reversed or doubled field, a temperature step); the cheapest
  variant after which no pair of the group stays indistinguishable is proposed. If none does,
  each member's independent check is reported (e.g. gravity and an unreferenced field act
  identically on the lever in every rotation: only levelling the plane or checking the
  reference's zero tells them apart).
- **Tie-break inside a group**: members within ΔBIC 2 of the group's best are ordered by
  (fitted parameters inside their physical bounds first, then catalog priority): physics whose
  size is fixed by known constants (static deflection, gravity, finite amplitude, damping,
  transverse gradient) before free calibration errors (field offset, plane tilt, moment scale).
- **Verdict**: ``effect_missing`` when the best candidate has ΔBIC > 10, p < 1e-3 and accounts
  for at least half of the excess χ² − dof; else ``adequate`` when χ² is consistent with its
  dof (p ≥ 0.005) and no structure is significant; else ``unexplained_structure``.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.stats

from mows.lab import effects as effects_module

HARMONICS = range(5)
STRUCTURE_ALPHA = 0.005  # family-wise, Bonferroni over harmonics and covariates
GROUP_COSINE = 0.95
GROUP_SIGNIFICANCE = 0.01
TIE_DELTA_BIC = 2.0
STRONG_DELTA_BIC = 10.0
STRONG_P = 1e-3
GOODNESS_ALPHA = 0.005  # with STRUCTURE_ALPHA: ≈ 1 % false alarms for a complete model
EXPLAINED_FRACTION = 0.5
RANK_RTOL = 1e-3  # a projected direction shorter than this (relative) is absorbed by the model
REFIT_P = 0.05


# --- linear algebra ---------------------------------------------------------------------------
def orthonormal_basis(columns, reference_norm=None) -> np.ndarray:
    """Orthonormal basis (n, r) of the column space, dropping directions below RANK_RTOL of
    ``reference_norm`` (default: the largest singular value)."""
    columns = np.asarray(columns, float).reshape(len(columns), -1)
    if columns.shape[1] == 0:
        return columns
    u, s, _ = np.linalg.svd(columns, full_matrices=False)
    scale = s[0] if reference_norm is None else reference_norm
    return u[:, s > RANK_RTOL * scale] if scale > 0 else u[:, :0]


def project_out(columns, basis) -> np.ndarray:
    """Columns with their components along the orthonormal ``basis`` removed."""
    return columns - basis @ (basis.T @ columns)


@dataclasses.dataclass
class Signature:
    """A test direction set after projection: basis U (n, r), coefficients of the residual."""

    basis: np.ndarray
    projected: np.ndarray
    statistic: float
    rank: int

    @property
    def p_value(self) -> float:
        return float(scipy.stats.chi2.sf(self.statistic, self.rank)) if self.rank else 1.0

    @property
    def fitted_signal(self) -> np.ndarray:
        return self.basis @ self.coefficients_in_basis

    coefficients_in_basis: np.ndarray = None
    columns: np.ndarray = None   # before projection


def signature(columns, model_basis, residual) -> Signature:
    """Project ``columns`` orthogonally to the model and score them against ``residual``."""
    columns = np.asarray(columns, float).reshape(len(residual), -1)
    projected = project_out(columns, model_basis)
    norm = np.linalg.norm(columns, axis=0).max() if columns.size else 0.0
    basis = orthonormal_basis(projected, norm)
    coefficients = basis.T @ residual
    return Signature(basis, projected, float(coefficients @ coefficients), basis.shape[1], coefficients, columns)


def _cosine_within(vector, basis) -> float:
    norm = np.linalg.norm(vector)
    return float(np.linalg.norm(basis.T @ vector) / norm) if norm > 0 and basis.shape[1] else 0.0


# --- residual structure -----------------------------------------------------------------------
@dataclasses.dataclass
class Harmonic:
    k: int
    amplitude_hz: float
    std_hz: float
    phase_rad: float
    p_value: float
    absorbed: bool


@dataclasses.dataclass
class CovariateTrend:
    name: str
    correlation: float
    slope: float
    p_value: float


@dataclasses.dataclass
class Structure:
    """Residual structure of a fit (module docstring). ``summary`` says it in words."""

    chi2: float
    dof: int
    goodness_p: float
    harmonics: list
    covariates: list
    alpha: float
    summary: str = ""

    @property
    def significant(self) -> list:
        """Descriptions of the significant features."""
        found = [f"harmonic {h.k} of θ0 ({h.amplitude_hz * 1e3:.3g} ± {h.std_hz * 1e3:.2g} mHz, "
                 f"phase {math.degrees(h.phase_rad):.0f}°, p = {h.p_value:.1e})"
                 for h in self.harmonics if not h.absorbed and h.p_value < self.alpha]
        found += [f"a trend with {c.name} (correlation {c.correlation:+.2f}, p = {c.p_value:.1e})"
                  for c in self.covariates if c.p_value < self.alpha]
        return found

    def to_dict(self) -> dict:
        return {"summary": self.summary, "chi2": self.chi2, "dof": self.dof, "goodness_p": self.goodness_p,
                "alpha": self.alpha,
                "harmonics": [dataclasses.asdict(h) for h in self.harmonics],
                "covariates": [dataclasses.asdict(c) for c in self.covariates]}


def residual_structure(fit) -> Structure:
    """Harmonics 0–4 and covariate trends of the fit's residual (module docstring)."""
    residual = fit.weighted_residual
    weight = 1.0 / fit.table.f_std_hz
    model_basis = orthonormal_basis(fit.jacobian)
    theta = fit.table.theta0_rad
    harmonics = []
    for k in HARMONICS:
        columns = np.column_stack([np.cos(k * theta), np.sin(k * theta)] if k else [np.ones_like(theta)]) * weight[:, None]
        harmonics.append(_harmonic(k, signature(columns, model_basis, residual), residual))
    trends = []
    for name, values in fit.table.covariates().items():
        test = signature((values - values.mean()) * weight, model_basis, residual)
        if test.rank:
            direction = test.projected[:, 0]
            trends.append(CovariateTrend(name, float(direction @ residual / (np.linalg.norm(direction) *
                                                                              np.linalg.norm(residual))),
                                         float(direction @ residual / (direction @ direction)), test.p_value))
    tests = sum(not h.absorbed for h in harmonics) + len(trends)
    structure = Structure(fit.chi2, fit.dof, float(scipy.stats.chi2.sf(fit.chi2, max(fit.dof, 1))), harmonics,
                          trends, STRUCTURE_ALPHA / max(tests, 1))
    structure.summary = _describe(structure)
    return structure


def _harmonic(k, test: Signature, residual) -> Harmonic:
    if not test.rank:
        return Harmonic(k, 0.0, 0.0, 0.0, 1.0, True)
    coefficients, *_ = np.linalg.lstsq(test.projected, residual, rcond=None)
    covariance = np.linalg.pinv(test.projected.T @ test.projected)
    c, s = (coefficients[0], coefficients[1]) if k else (coefficients[0], 0.0)
    amplitude = math.hypot(c, s)
    gradient = np.array([c, s])[: len(coefficients)] / amplitude if amplitude > 0 else np.ones(len(coefficients))
    std = float(np.sqrt(gradient @ covariance @ gradient))
    return Harmonic(k, amplitude, std, math.atan2(-s, c), test.p_value, False)


def _describe(structure: Structure) -> str:
    reduced = structure.chi2 / max(structure.dof, 1)
    head = (f"χ²/dof = {reduced:.3g} over {structure.dof} degrees of freedom "
            f"(p = {structure.goodness_p:.2g}): "
            + ("consistent with the stated uncertainties" if structure.goodness_p >= GOODNESS_ALPHA
               else "the residuals exceed the stated uncertainties"))
    found = structure.significant
    if found:
        return head + ". Significant structure: " + "; ".join(found) + "."
    if structure.goodness_p < GOODNESS_ALPHA:
        return (head + ". No harmonic of θ0 up to 4 and no covariate trend stands out: the excess looks "
                f"like white scatter (f_std_hz ≈ ×{math.sqrt(reduced):.2f} too small, or noise the "
                "model does not describe).")
    return head + ". No significant structure: the residuals look like noise."


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
    fit: object = None
    signal_chi2: float = math.nan  # at physics: Σ(predicted signal/σ)² beyond what f00 absorbs

    @property
    def chi2_dof_after(self) -> float:
        return self.chi2_after / max(self.dof_after, 1)

    @property
    def kept_physics(self) -> bool:
        """Known physics the data cannot reject: held at physics, its predicted signal would be
        strong evidence if no free parameter absorbed it, and adding it costs less than the
        tie margin of BIC (how :mod:`mows.lab.analysis` uses it)."""
        return self.fixed and self.signal_chi2 > STRONG_DELTA_BIC and self.delta_bic > -TIE_DELTA_BIC

    def to_dict(self) -> dict:
        return {"delta_bic": _finite(self.delta_bic), "p_value": _finite(self.p_value),
                "chi2_dof_after": _finite(self.chi2_dof_after)}


@dataclasses.dataclass
class Candidate:
    """One effect tested against the current fit (fields map onto mows_msgs/CandidateEffect).

    Effects with a physical value are tested in both forms (``free`` and ``physics``); the
    candidate stands for the better of the two by BIC (:attr:`form`; the fewer parameters on a
    tie): ``delta_bic``, ``p_value`` and ``chi2_dof_after`` are that form's (:attr:`chosen`).
    ``parameters`` are always the free fit's, so that a candidate held at physics still shows
    how far its physical value lies from what the data say alone (:attr:`physics_deviation`).
    """

    effect: effects_module.Effect
    free: Form
    physics: Form | None
    score_p_value: float
    parameters: list          # [(name, value, std, unit)] of the free form
    within_bounds: bool
    signature: Signature
    group: int = 0

    @property
    def name(self) -> str:
        return self.effect.name

    @property
    def chosen(self) -> Form:
        return self.physics if self.physics is not None and self.physics.delta_bic >= self.free.delta_bic else self.free

    @property
    def forms(self) -> list:
        return [self.free] + ([self.physics] if self.physics is not None else [])

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
        return self.delta_bic > STRONG_DELTA_BIC and self.p_value < STRONG_P

    def to_dict(self) -> dict:
        return {"effect": self.name, "form": self.form, "label": self.label, "delta_bic": _finite(self.delta_bic),
                "p_value": _finite(self.p_value), "score_p_value": _finite(self.score_p_value),
                "chi2_dof_after": _finite(self.chi2_dof_after),
                "parameters": {name: {"value": v, "std": s, "unit": u} for name, v, s, u in self.parameters},
                "free": self.free.to_dict(), "at_physics": None if self.physics is None else self.physics.to_dict(),
                "physics_deviation_sigma": _finite(self.physics_deviation),
                "within_bounds": self.within_bounds, "group": self.group, "explanation": self.effect.explanation}


def physics_deviation(effect, parameters) -> float:
    """Largest |value − physical value|/σ of an effect's fitted ``parameters`` [(name, value,
    std, unit)]; NaN when the effect has no physical value."""
    if effect.physical is None or not parameters:
        return math.nan
    return max(abs(v - p) / s if s > 0 else math.inf for (_, v, s, _), p in zip(parameters, effect.physical))


@dataclasses.dataclass
class Group:
    """Candidates this data cannot tell apart, the measurement that would, and direct checks."""

    number: int
    members: list
    separated_by: str | None
    separation: str
    checks: list

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


@dataclasses.dataclass
class Diagnosis:
    fit: object
    structure: Structure
    candidates: list
    groups: list
    untestable: dict
    verdict: str
    explanation: str

    @property
    def best(self):
        return self.candidates[0] if self.candidates else None


def _finite(value):
    return float(value) if np.isfinite(value) else None


def diagnose(fit, effects, probe=None) -> Diagnosis:
    """Rank ``effects`` (an iterable of :class:`Effect`, those already in the model are skipped)
    as explanations of ``fit``'s residual; group, propose separating measurements, verdict."""
    probe = probe or fit.model.probe
    candidates, untestable = rank_candidates(fit, effects, probe)
    groups = _group(candidates, fit, probe)
    structure = residual_structure(fit)
    verdict, explanation = _verdict(fit, structure, candidates)
    return Diagnosis(fit, structure, candidates, groups, untestable, verdict, explanation)


def rank_candidates(fit, effects, probe, worth_refit=None) -> tuple:
    """(candidates best first, {effect: why it cannot be tested}) for the ``effects`` not yet in
    ``fit``'s model: score test on the projected signature, then each form's refit where
    ``worth_refit(effect, signature, added)`` (``added``: the free parameters the form adds;
    default: score p < REFIT_P), else the one-step estimate."""
    worth_refit = worth_refit or (lambda effect, test, added: test.p_value < REFIT_P)
    residual = fit.weighted_residual
    model_basis = orthonormal_basis(fit.jacobian)
    candidates, untestable = [], {}
    for effect in effects:
        if effect.name in fit.model.effect_names:
            continue
        reason = effects_module.testable(effect, fit.table, probe)
        test = None if reason else signature(fit.extension_columns(effect), model_basis, residual)
        if test is not None and not test.rank:
            reason = "no signature in this table that the current model cannot already absorb"
        if reason:
            untestable[effect.name] = reason
            continue
        candidates.append(_candidate(fit, effect, test, lambda added: worth_refit(effect, test, added)))
    candidates.sort(key=lambda c: -c.delta_bic)
    return candidates, untestable


def _candidate(fit, effect, test: Signature, refit) -> Candidate:
    """Refit the model with ``effect`` in each form where ``refit(added free parameters)``, or
    take the one-step (linearised) refit along the projected signature. A Δχ² above the strong
    threshold needs a score statistic above it too (the score is the largest Δχ² of the
    linearised problem), so with the default rule no strong form is left to the one-step
    estimate."""
    free, parameters = _free_form(fit, effect, test, refit(len(effect.parameters)))
    physics = None if effect.physical is None else _physics_form(fit, effect, test, refit(0))
    inside = all(p.lower + 1e-6 * (p.upper - p.lower) < v < p.upper - 1e-6 * (p.upper - p.lower)
                 for p, (_, v, _, _) in zip(effect.parameters, parameters))
    return Candidate(effect, free, physics, test.p_value, parameters, inside, test)


def _free_form(fit, effect, test: Signature, refit: bool) -> tuple:
    """(Form, parameters) of ``effect`` added with its parameters free."""
    k = len(effect.parameters)
    if refit:
        after = (fit.model + effect).fit(fit.table, start=np.concatenate([fit.values[1:], np.zeros(k)]))
        chi2_after, dof_after, parameters = after.chi2, after.dof, after.effect_parameters(effect.name)
    else:
        after = None
        step = -np.linalg.pinv(test.projected) @ fit.weighted_residual
        std = np.sqrt(np.clip(np.diag(np.linalg.pinv(test.projected.T @ test.projected)), 0, None))
        chi2_after, dof_after = fit.chi2 - test.statistic, fit.dof - test.rank
        parameters = [(p.name, float(v), float(e), p.unit) for p, v, e in zip(effect.parameters, step, std)]
    gain = fit.chi2 - chi2_after
    form = Form(False, gain - k * math.log(fit.n), float(scipy.stats.chi2.sf(max(gain, 0.0), test.rank)),
                chi2_after, dof_after, after)
    return form, parameters


def _physics_form(fit, effect, test: Signature, refit: bool) -> Form:
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
    predicted = test.columns @ np.asarray(effect.physical, float)
    signal = project_out(predicted[:, None], orthonormal_basis(fit.jacobian[:, :1]))
    if refit:
        after = (fit.model + effect.at_physics()).fit(fit.table, start=fit.values[1:])
        shift, chi2_after, dof_after = after.weighted_residual - residual, after.chi2, after.dof
    else:
        after = None
        shift = test.projected @ np.asarray(effect.physical, float)
        chi2_after, dof_after = float(np.sum((residual + shift) ** 2)), fit.dof
    gain = fit.chi2 - chi2_after
    size = float(np.linalg.norm(shift))
    p = float(scipy.stats.norm.sf((gain + size**2) / (2 * size))) if size > 0 else 1.0
    return Form(True, gain, p, chi2_after, dof_after, after, float(np.sum(signal**2)))


# --- groups and separating measurements ---------------------------------------------------------
def _indistinguishable(a: Signature, b: Signature) -> bool:
    return (_cosine_within(a.fitted_signal, b.basis) >= GROUP_COSINE and
            _cosine_within(b.fitted_signal, a.basis) >= GROUP_COSINE)


def _clusters(significant) -> list:
    """Connected sets (of two or more) of indistinguishable candidates, each in tie-break order."""
    by_name = {c.name: c for c in significant}
    parts = _partition({c.name: c.signature for c in significant})
    return [_tie_break([by_name[name] for name in part]) for part in parts if len(part) > 1]


def _group(candidates, fit, probe) -> list:
    """Number the groups by rank, put each group's members together in tie-break order
    (``candidates`` is reordered in place) and find what separates each group."""
    cluster_of = {c.name: members for members in _clusters([c for c in candidates if c.p_value < GROUP_SIGNIFICANCE])
                  for c in members}
    ranked, groups = [], []
    for candidate in candidates:
        members = cluster_of.get(candidate.name)
        if members is None:
            ranked.append(candidate)
        elif members[0] not in ranked:
            for member in members:
                member.group = len(groups) + 1
            ranked.extend(members)
            groups.append(_separate(members, fit, probe, len(groups) + 1))
    candidates[:] = ranked
    return groups


def _tie_break(members) -> list:
    members = sorted(members, key=lambda c: -c.delta_bic)
    best = members[0].delta_bic
    tied = [c for c in members if c.delta_bic >= best - TIE_DELTA_BIC]
    rest = [c for c in members if c not in tied]
    return sorted(tied, key=lambda c: (not c.within_bounds, c.effect.priority)) + rest


def _partition(signatures: dict) -> list:
    """Connected sets of mutually indistinguishable signatures (names), singletons included."""
    names = list(signatures)
    parent = {name: name for name in names}

    def root(name):
        while parent[name] != name:
            name = parent[name]
        return name

    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if _indistinguishable(signatures[a], signatures[b]):
                parent[root(b)] = root(a)
    found = {}
    for name in names:
        found.setdefault(root(name), []).append(name)
    return list(found.values())


def _separate(members, fit, probe, number) -> Group:
    """The cheapest what-if variant that splits the group most; checks for what stays together."""
    names = [c.name for c in members]
    best_variant, best_parts = None, [names]
    # The fitted signal extended to new rows: the same linear coefficients on the joined rows.
    coefficients = {c.name: np.linalg.lstsq(c.signature.projected, c.signature.fitted_signal, rcond=None)[0]
                    for c in members}
    for variant in variants(fit.table, probe):
        joined = variant.table
        model_basis = orthonormal_basis(fit.model_jacobian(joined))
        extended = {}
        for candidate in members:
            columns = np.asarray(fit.extension_columns(candidate.effect, joined))
            projected = project_out(columns, model_basis)
            basis = orthonormal_basis(projected, np.linalg.norm(columns, axis=0).max())
            extended[candidate.name] = Signature(basis, projected, 0.0, basis.shape[1],
                                                 basis.T @ (projected @ coefficients[candidate.name]))
        parts = _partition(extended)
        if len(parts) > len(best_parts):
            best_variant, best_parts = variant, parts
        if len(parts) == len(names):
            break
    together = [part for part in best_parts if len(part) > 1]
    checks = [f"{name}: {next(c for c in members if c.name == name).effect.check}" for part in together for name in part]
    if best_variant is None:
        text = ("no variation of angles, amplitude, field or temperature separates them: they act identically "
                "on the lever; check directly")
    else:
        text = f"{best_variant.description}: separates " + " | ".join(", ".join(part) for part in best_parts)
        if together:
            text += "; " + "; ".join(", ".join(part) for part in together) + " still act identically: check directly"
    return Group(number, names, None if best_variant is None else best_variant.name, text, checks)


@dataclasses.dataclass
class Variant:
    """A what-if measurement: ``table`` holds the present rows followed by the extra ones."""

    name: str
    description: str
    table: object


def variants(table, probe) -> list:
    """What-if variants of ``table``, cheapest first (module docstring)."""
    if not table.has("amplitude_deg"):  # a missing amplitude is the stop's (Configuration.base)
        table = table.with_columns(amplitude_deg=np.full(len(table), math.degrees(probe.theta_stop_rad)))
    found = []
    angles = np.unique(np.mod(table.columns["theta0_deg"], 360.0))
    step = float(np.median(np.diff(angles))) if len(angles) > 1 else 90.0
    found.append(Variant("more_angles", f"measure also half-way between the present orientations "
                                        f"(θ0 + {step / 2:g}°)",
                         table.with_columns(theta0_deg=table.columns["theta0_deg"] + step / 2)))
    found.append(Variant("amplitude_halved", "repeat the sweep at half the excitation amplitude",
                         table.with_columns(amplitude_deg=table.amplitude_deg / 2)))
    for name, factor, text in (("field_reversed", -1.0, "repeat with the applied field reversed (coil currents "
                                                        "reversed)"),
                               ("field_doubled", 2.0, "repeat with twice the applied field")):
        scaled = {k: v * factor for k, v in table.columns.items() if k.startswith("ref_") or k == "coil_current_a"}
        found.append(Variant(name, text, table.with_columns(**scaled)))
    if table.has("temperature_k"):
        found.append(Variant("temperature_step", "repeat 5 K warmer (or colder)",
                             table.with_columns(temperature_k=table.temperature_k + 5.0)))
    return [dataclasses.replace(variant, table=table.concatenate(variant.table)) for variant in found]


# --- verdict ------------------------------------------------------------------------------------
def _verdict(fit, structure: Structure, candidates) -> tuple:
    best = candidates[0] if candidates else None
    excess = fit.chi2 - fit.dof
    if best is not None and best.strong:
        gain = fit.chi2 - best.chosen.chi2_after
        if gain >= EXPLAINED_FRACTION * excess:
            group = f" (group {best.group}: the data cannot tell it from " \
                    f"{', '.join(c.name for c in candidates if c.group == best.group and c is not best)})" \
                if best.group else ""
            return "effect_missing", (f"{best.label} is missing{group}: ΔBIC = {best.delta_bic:.1f}, "
                                      f"p = {best.p_value:.1e}, "
                                      f"χ²/dof {fit.chi2_dof:.3g} → {best.chi2_dof_after:.3g}.")
        unexplained = (f"The best candidate, {best.label} (ΔBIC = {best.delta_bic:.1f}), accounts for only "
                       f"{100 * gain / excess:.0f}% of the excess χ². ")
    else:
        unexplained = "No catalog effect explains the residual." if candidates else ""
    if structure.goodness_p >= GOODNESS_ALPHA and not structure.significant:
        return "adequate", "The model explains the data: " + structure.summary
    return "unexplained_structure", (unexplained + " " + structure.summary).strip()
