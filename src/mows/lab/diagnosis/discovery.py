"""Discovery beyond the catalog: which terms of the rows' covariates the residual follows, when no
catalog effect explains it, each with the plugin that writes it as physics (docs/model_lab.md).

**Library.** The factors are the rows' covariates in the probe frame (:data:`FACTORS`): the
reference field B∥ = Bx', B⊥ = By', |B|, Bz and the gradient Gx'x', Gx'y', Gy'y'; temperature T,
time t, coil current I, the table's start swing ``amplitude_deg``; the model's own rest angle θs
and start swing at the reference in full (:func:`model_covariates`); and cos kθ0, sin kθ0 for
k = 1…4. Only those the table has, and not constant. The terms are the factors and their products
and squares up to :data:`DEGREE` (2), but no product of two angle harmonics (that is another
harmonic). Factors whose zero is arbitrary (extra columns) are centred on the table's mean
before they multiply, the temperature on the probe's reference temperature (where its constants
hold: a moment's temperature coefficient is then one term, not that and a scale error); those
with a physical zero (fields, current, swings, harmonics, and time from the table's start, where
the probe's constants were last known to hold) are not, so that coil heating is one term, I², and
not I² and I of a centred current, and a moment that ages is one term, B∥·t.

**What is searched.** Each term x, weighted by 1/σ, is projected orthogonally to the current fit's
Jacobian (:mod:`mows.lab.diagnosis.projections`: only what the model's free parameters cannot
absorb), and scaled to unit length; the target is the weighted residual r = (f − model)/σ. Terms
the model absorbs (left with < 1e-3 of their length) are dropped, and of terms the rows cannot
tell apart (|cos| ≥ 0.999) the first in library order is kept and the others are its ``aliases``.

**Sparse regression.** The lasso path by LARS (scikit-learn's ``lars_path``), stopped by the
noise: the next term enters only while its correlation with the residual exceeds the Bonferroni
threshold over the library times the residual scatter of the terms already in (at least 1, the
stated σ). This is the scaled lasso's rule on the path: a penalty at the noise level, with the
noise estimated from what the terms leave, so that a residual 100× its noise still lets its
leading term in and not the ones the leading term explains. It is scikit-learn, not PySINDy:
the problem is a static regression of residuals on covariates, not the identification of
dynamics x' = Θ(x)·ξ that PySINDy is built for; PySINDy's STLSQ would work on the same library but
adds nothing here, and LARS gives the whole path for one least-squares solve.

**Stability selection.** The path runs on :data:`RESAMPLES` half-samples (complementary pairs,
seeded) of the current model's configuration groups (rows the model cannot tell apart; the rows
themselves when there are fewer than :data:`MIN_UNITS` groups), each re-projected against the
model's Jacobian on its rows. A term is kept when it is selected in at least
:data:`STABLE_FRACTION` of them. A table longer than :data:`MAX_ROWS` is searched on that many
stratified rows (:func:`mows.lab.data.table.stratified_rows`: whole sweeps spread over the table),
so that the search stays within a fraction of a second and a few megabytes.

**Refit and gain.** The kept terms are refitted jointly by weighted least squares on the projected
columns (the model's parameters free, Frisch–Waugh) for their strengths, Hz per unit of the term
in the covariates' physical units, with σ inflated by the scatter they leave (φ = max(1, χ²/dof)).
A term is reported only when (a) its likelihood-ratio p-value, Δχ²/φ ~ χ²(1), is below
:data:`ALPHA` divided by the library size (Bonferroni) and (b) its cross-validated gain is
positive: the held-out χ² over the grouped folds (:func:`mows.lab.data.folds.cv_folds`), each fold
predicted by the linearised refit of the model's parameters and the other terms on the rest,
without the term minus with it. The weakest failing term is dropped and the rest refitted, until
every term passes.

**Physical form.** Each term's family follows from the kinds of its factors (:data:`RULES`), and
with it the reading and the plugin output that writes it as physics (field × X: the moment
changes with X; a slow covariate alone, or I²: the spring; A², θs²: a stiffening hinge; harmonic
1: a field the reference misses; Bz × harmonic 1: a tilt; else an additive frequency). The plugin's
parameter is fitted on the same projected residual through the plugin's own signature
(:meth:`FitResult.extension_columns`); where that signature does not reproduce the term
(|cos| < :data:`PHYSICAL_COSINE`), the plugin is the additive frequency term.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import textwrap
import warnings
from collections.abc import Sequence

import numpy as np
import scipy.stats

from mows.lab import progress
from mows.lab.data.folds import cv_folds
from mows.lab.data.probe_rows import ProbeSet, probe_parts
from mows.lab.data.table import KNOWN, LABELS, MAGNET, NEIGHBOUR, NOT_COVARIATES, MeasurementTable, stratified_rows
from mows.lab.diagnosis.projections import RANK_RTOL, SPAN_COSINE, orthonormal_basis, project_out, unit_columns
from mows.lab.model.configuration import Configuration
from mows.lab.model.effects import Effect
from mows.lab.model.frequency_model import FrequencyModel
from mows.lab.model.least_squares import FitResult, FittedParameter
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe
from mows.records.json_numbers import finite_or_none

DEGREE = 2  # products and squares of up to this many factors
HARMONICS = range(1, 5)  # cos kθ0, sin kθ0
RESAMPLES = 100  # half-samples of the stability selection (50 complementary pairs)
SCREEN_RESAMPLES = 40  # … for the search's stand-ins (plugins=False), a screen that reports nothing
STABLE_FRACTION = 0.8  # a term is kept when selected in at least this fraction of them
SELECTION_ALPHA = 0.05  # family-wise level over the library of one half-sample's path
ALPHA = 0.01  # family-wise level (Bonferroni over the library) of a reported term
MAX_TERMS = 6  # steps of one path: a sparse answer has a few terms
MIN_UNITS = 8  # fewer configuration groups than this: half-samples of rows
MIN_ROWS = 12  # fewer rows than this say nothing on a library of terms
MAX_ROWS = 20_000  # a longer table is searched on this many stratified rows (whole sweeps first)
PHYSICAL_COSINE = 0.95  # a plugin's signature at least this close to the term's writes it
FAMILIES = (
    "field_squared",
    "field_times_temperature",
    "field_times_time",
    "temperature",
    "time",
    "current_squared",
    "current",
    "field_times_current",
    "amplitude_squared",
    "angle_harmonic",
    "field_z",
    "gradient",
    "other",
)


@dataclasses.dataclass(frozen=True)
class Factor:
    """A covariate a term may hold: its kind (what the family rules read), unit, and whether it
    is centred on the table's mean before it multiplies (no physical zero)."""

    name: str
    kind: str
    unit: str
    centred: bool = False


FIELD_FACTORS = ("b_along_t", "b_perp_t", "b_abs_t")
GRADIENT_FACTORS = ("g_t_per_m", "g_xy_t_per_m", "g_yy_t_per_m")
MODEL_FACTORS = ("start_swing_rad", "rest_angle_rad")  # the model's own, at the reference in full
DERIVED_FACTORS = (*FIELD_FACTORS, "b_normal_t", *GRADIENT_FACTORS)  # MeasurementTable.derived_columns
TABLE_FACTORS = ("temperature_k", "t_s", "coil_current_a", "amplitude_deg")
# Library order: what is kept of terms the rows cannot tell apart (the first) and how names read.
FACTORS = (
    *(Factor(name, "field", "T") for name in FIELD_FACTORS),
    Factor("b_normal_t", "field_z", "T"),
    *(Factor(name, "gradient", "T/m") for name in GRADIENT_FACTORS),
    Factor("temperature_k", "temperature", "K", centred=True),
    Factor("t_s", "time", "s"),
    Factor("coil_current_a", "current", "A"),
    Factor("amplitude_deg", "swing", "deg"),
    *(Factor(name, "swing", "rad") for name in MODEL_FACTORS),
    *(Factor(f"{trig}({k}θ0)", "angle", "1") for k in HARMONICS for trig in ("cos", "sin")),
)
# Columns that are not covariates of their own: labels, inputs of the model, the measurement.
NOT_EXTRA = set(KNOWN) | NOT_COVARIATES | set(LABELS) | set(MAGNET) | set(NEIGHBOUR)


@dataclasses.dataclass(frozen=True)
class Rule:
    """A family of terms (by the kinds of their factors): its physical reading and the plugin
    output that writes it as physics."""

    family: str
    reading: str
    output: str


MOMENT, SPRING, FIELD, TILT, FREQUENCY = (
    "moment_scale",
    "stiffness_nm_per_rad",
    "field_offset_t",
    "tilt_rad",
    "frequency_hz",
)
_TEMPERATURE = Rule("field_times_temperature", "the moment's temperature coefficient", MOMENT)
_TIME = Rule("field_times_time", "the moment ageing or demagnetising", MOMENT)
_CURRENT = Rule(
    "field_times_current", "the moment changes with the coil current (the coil heats or magnetises the magnet)", MOMENT
)
# Sorted kinds of a term's factors → its rule. Terms with Bz are field_z, other terms with a
# gradient factor are gradient, anything else not listed is other (:func:`rule_of`).
RULES: dict[tuple[str, ...], Rule] = {
    ("field", "field"): Rule(
        "field_squared", "induced magnetisation (a susceptibility): a moment that grows with the field", MOMENT
    ),
    ("field", "temperature"): _TEMPERATURE,
    ("gradient", "temperature"): _TEMPERATURE,
    ("field", "time"): _TIME,
    ("gradient", "time"): _TIME,
    ("current", "field"): _CURRENT,
    ("current", "gradient"): _CURRENT,
    ("temperature",): Rule("temperature", "the spring's temperature coefficient", SPRING),
    ("temperature", "temperature"): Rule("temperature", "the spring's temperature coefficient, curved", SPRING),
    ("time",): Rule("time", "spring creep or drift", SPRING),
    ("time", "time"): Rule("time", "spring creep or drift, curved", SPRING),
    ("temperature", "time"): Rule("other", "a spring drift whose rate depends on temperature", SPRING),
    ("current", "current"): Rule("current_squared", "Ohmic heat of the coil warming the spring", SPRING),
    ("current",): Rule("current", "a field the reference misses, proportional to the coil current", FREQUENCY),
    ("swing", "swing"): Rule("amplitude_squared", "a non-linear (stiffening) hinge", SPRING),
    ("angle",): Rule("angle_harmonic", "geometry: a field the reference misses, a tilt, an angle offset", FREQUENCY),
    ("field",): Rule("other", "the field's spring scaled: the moment (β0) is off, the catalog's moment_scale", MOMENT),
}
FIELD_Z = Rule("field_z", "an out-of-plane field acting through a tilt of the plane", FREQUENCY)
GRADIENT = Rule("gradient", "a gradient the model misses or misweights (transverse parts, lever, curvature)", FREQUENCY)
OTHER = Rule("other", "", FREQUENCY)
WHY = {
    MOMENT: "the moment changes with it, in every magnetic term of the potential",
    SPRING: "the spring changes with it",
    FIELD: "a field the reference misses, through the potential",
    TILT: "the plane's tilt turns Bz into the plane",
    FREQUENCY: "an additive frequency term (a readout term, no physics); better the physics that makes it",
}


def rule_of(factors: Sequence[str]) -> Rule:
    """The family rule of a term with ``factors`` (names of :data:`FACTORS` or extra columns)."""
    kinds = tuple(sorted(_factor(name).kind for name in factors))
    if "field_z" in kinds:
        return FIELD_Z
    if kinds in RULES:
        return RULES[kinds]
    return GRADIENT if "gradient" in kinds else OTHER


def _factor(name: str) -> Factor:
    return next((f for f in FACTORS if f.name == name), Factor(name, "extra", f"[{name}]", centred=True))


@dataclasses.dataclass(frozen=True)
class TermFit:
    """What a term's strength is fitted to, row by row on the rows searched (a picture's numbers):
    the term beyond what the model absorbs (its weighted column projected off the model's
    Jacobian, over the row's weight w = 1/σ: in the term's unit) and the residual it explains (the
    weighted residual less the other kept terms' fits, over w: Hz), with each row's σ (Hz). The
    weighted least-squares slope of ``residual_hz`` on ``beyond_model`` is the term's strength."""

    beyond_model: np.ndarray
    residual_hz: np.ndarray
    std_hz: np.ndarray


@dataclasses.dataclass
class DiscoveredTerm:
    """A term the residual follows beyond the catalog (module docstring)."""

    name: str  # factors joined by "·", e.g. "b_along_t·temperature_k"; a square "coil_current_a²"
    factors: tuple[str, ...]
    family: str  # one of FAMILIES
    strength: float  # Hz per unit of the term (physical units)
    std: float  # its σ, Hz per unit
    selection_frequency: float  # fraction of the half-samples that kept it
    cv_gain_chi2: float  # held-out χ² without minus with the term
    reading: str  # the family's physical reading in words ("" if none)
    plugin: str  # a plugin file's source that writes the term in its physical form
    unit: str = "1"  # the term's unit (product of its factors' units)
    p_value: float = math.nan  # of Δχ²/φ ~ χ²(1), before the Bonferroni factor
    aliases: tuple[str, ...] = ()  # library terms identical to it on these rows
    plugin_parameter: FittedParameter | None = None  # the plugin's parameter fitted on this table
    plugin_output: str = FREQUENCY  # the plugin output that writes it
    plugin_line: str = ""  # the plugin on one line, for explanations
    fitted: TermFit | None = dataclasses.field(default=None, compare=False, repr=False)

    @property
    def strength_unit(self) -> str:
        return per_unit(self.unit)

    @property
    def effect_name(self) -> str:
        """The plugin's effect (and file) name."""
        return plugin_name(self.factors)

    def text(self) -> str:
        """One line: name, strength ± σ, stability, gain, reading."""
        reading = f": {self.reading}" if self.reading else ""
        alias = f" (on these rows the same as {', '.join(self.aliases)})" if self.aliases else ""
        return (
            f"{self.name}{alias} ({self.strength:+.3g} ± {self.std:.2g} {self.strength_unit}, selected in "
            f"{100 * self.selection_frequency:.0f}% of the half-samples, held-out χ² −{self.cv_gain_chi2:.1f}; "
            f"{self.family}{reading})"
        )

    def to_dict(self) -> dict:
        found = dataclasses.asdict(dataclasses.replace(self, fitted=None))
        del found["fitted"]
        found["factors"], found["aliases"] = list(self.factors), list(self.aliases)
        found["strength_unit"] = self.strength_unit
        found["plugin_parameter"] = (
            None
            if self.plugin_parameter is None
            else {"name": self.plugin_parameter.name, **self.plugin_parameter.to_dict()}
        )
        return finite_or_none(found)


@dataclasses.dataclass
class Discovery:
    """What :func:`discover` found: the terms, best first, and how hard it looked."""

    terms: list[DiscoveredTerm]
    library: int  # terms searched
    resamples: int
    degree: int
    summary: str  # one or two sentences for the report
    on_model: str = ""  # the model whose residual was searched
    # The terms as additive frequency effects with free strengths: a stand-in for the physics
    # outside the catalog, beside which the search judges catalog effects.
    stand_ins: tuple[Effect, ...] = ()

    def to_dict(self) -> dict:
        return {
            "terms": [t.to_dict() for t in self.terms],
            "library": self.library,
            "resamples": self.resamples,
            "degree": self.degree,
            "summary": self.summary,
            "on_model": self.on_model,
        }

    def lines(self) -> list[str]:
        """The text report's lines: what was searched, one line per term, the strongest's plugin file."""
        head = f"discovery beyond the catalog, on {self.on_model}:"
        if not self.terms:
            return [head, "  " + self.summary]
        found = [head + f" {self.library} terms up to degree {self.degree}, {self.resamples} half-samples"]
        found += [f"  {i}. {term.text()}" for i, term in enumerate(self.terms, 1)]
        found.append(f"  plugin for the strongest, to save as {self.terms[0].effect_name}.py:")
        return found + ["    " + line if line else "" for line in self.terms[0].plugin.splitlines()]


# --- the library --------------------------------------------------------------------------------
@dataclasses.dataclass
class Term:
    """A library term: its factors, its values on the rows (physical units) and unit."""

    factors: tuple[str, ...]
    values: np.ndarray

    @property
    def name(self) -> str:
        return term_name(self.factors)

    @property
    def unit(self) -> str:
        return term_unit(self.factors)


def term_name(factors: Sequence[str]) -> str:
    """The factors joined by "·", a square as "x²": ``b_along_t·temperature_k``, ``coil_current_a²``."""
    if len(factors) == 2 and factors[0] == factors[1]:
        return f"{factors[0]}²"
    return "·".join(factors)


def term_unit(factors: Sequence[str]) -> str:
    """The unit of a product of ``factors``: their units, a repeated one squared, "1" for none."""
    units = [_factor(name).unit for name in factors if _factor(name).unit != "1"]
    counted = [(unit, units.count(unit)) for unit in dict.fromkeys(units)]
    return "·".join(unit + ("²" if count == 2 else "") for unit, count in counted) or "1"


def model_covariates(table: MeasurementTable, probe: Probe) -> dict[str, np.ndarray]:
    """The model's rest angle θs and start swing of every row (rad), at the table's reference in
    full and the probe's stop, as :func:`mows.lab.model.frequency_model.table_start_swing_rad` takes
    them; ``table``'s own rows, each probe of a :class:`ProbeSet` with its constants."""
    found = {name: np.empty(len(table)) for name in MODEL_FACTORS}
    for rows, member in probe_parts(table, probe):
        part = table if rows is None else table.subset(rows)
        config = Configuration.base(part, member)
        _, field, gradient, _ = config.probe_frame()
        potential = ArcPotential.from_local_field(
            member, field, gradient, None, None, spring_nm_per_rad=config.spring_nm_per_rad
        )
        index = slice(None) if rows is None else rows
        found["rest_angle_rad"][index] = potential.rest_angle_rad()
        found["start_swing_rad"][index] = config.start_swing_rad(potential)
    return found


def factor_values(table: MeasurementTable, probe: Probe) -> dict[str, np.ndarray]:
    """Every factor the table has (:data:`FACTORS`, then its extra numeric columns), in physical
    units, centred where the factor has no physical zero; constant or non-finite ones left out."""
    derived = table.derived_columns()
    found = {name: derived[name] for name in DERIVED_FACTORS if name in derived}
    found.update({name: table.columns[name] for name in TABLE_FACTORS if table.has(name)})
    distinct, inverse = FrequencyModel(probe).groups(table)
    found.update({name: values[inverse] for name, values in model_covariates(distinct, probe).items()})
    theta0 = table.theta0_rad
    found.update({f"{trig}({k}θ0)": getattr(np, trig)(k * theta0) for k in HARMONICS for trig in ("cos", "sin")})
    found.update({name: values for name, values in table.columns.items() if name not in NOT_EXTRA})
    usable = {name: values for name, values in found.items() if np.isfinite(values).all() and np.ptp(values) > 0}
    centres = factor_centres(usable, probe)
    return {name: values - centres[name] if name in centres else values for name, values in usable.items()}


def factor_centres(factors: dict[str, np.ndarray], probe: Probe) -> dict[str, float]:
    """What the centred factors are measured from: the temperature from the probe's reference
    temperature (where kM and m are given, so that a moment's temperature coefficient is one term
    and not a term and a moment-scale error), the others from the table's mean. Six digits: exact
    enough for a plugin's text (1e-6 of T moves a moment by c·3e-4 K)."""
    return {
        name: float(probe.reference_temperature_k if name == "temperature_k" else f"{np.mean(values):.6g}")
        for name, values in factors.items()
        if _factor(name).centred
    }


def library(factors: dict[str, np.ndarray], degree: int = DEGREE) -> list[Term]:
    """The factors and their products up to ``degree``, without products of angle harmonics."""
    names = list(factors)
    terms = []
    for size in range(1, degree + 1):
        for chosen in itertools.combinations_with_replacement(names, size):
            if sum(_factor(name).kind == "angle" for name in chosen) > 1:
                continue
            terms.append(Term(chosen, np.prod([factors[name] for name in chosen], axis=0)))
    return terms


@dataclasses.dataclass
class Searched:
    """The library as searched: the terms kept, their weighted columns (centred, unprojected) and
    projected unit columns, the projected length of each (physical units per unit column), and
    each kept term's aliases."""

    terms: list[Term]
    weighted: np.ndarray  # (n, L) w·(x − x̄)
    unit: np.ndarray  # (n, L) P⊥ of those, unit length
    length: np.ndarray  # (L,) |P⊥ w·(x − x̄)|
    aliases: list[list[str]]


def searchable(terms: list[Term], weight: np.ndarray, model_basis: np.ndarray) -> Searched:
    """Project every term orthogonally to the model, drop those it absorbs, keep the first of
    terms the rows cannot tell apart (module docstring)."""
    weighted = np.column_stack([(t.values - t.values.mean()) * weight for t in terms])
    before = np.linalg.norm(weighted, axis=0)
    projected = project_out(weighted, model_basis)
    length = np.linalg.norm(projected, axis=0)
    free = np.flatnonzero((before > 0) & (length > RANK_RTOL * before))
    unit = projected[:, free] / length[free]
    cosines = np.abs(unit.T @ unit)
    kept: list[int] = []
    aliases: dict[int, list[str]] = {}
    for j in range(len(free)):
        twin = next((i for i in kept if cosines[i, j] >= SPAN_COSINE), None)
        if twin is None:
            kept.append(j)
            aliases[j] = []
        else:
            aliases[twin].append(terms[free[j]].name)
    chosen = free[kept]
    return Searched(
        [terms[i] for i in chosen], weighted[:, chosen], unit[:, kept], length[chosen], [aliases[j] for j in kept]
    )


# --- sparse regression and stability selection ----------------------------------------------------
def threshold(library_size: int, alpha: float) -> float:
    """|z| above which one of ``library_size`` unit-noise scores is significant at family-wise ``alpha``."""
    return float(scipy.stats.norm.isf(alpha / (2 * max(library_size, 1))))


def lasso_selection(columns: np.ndarray, residual: np.ndarray, model_rank: int, z: float) -> np.ndarray:
    """Indices the lasso path selects before the noise stops it (module docstring): the terms in
    at the first knot where the next term's correlation falls below ``z``·σ̂, σ̂ the scatter left
    by the terms in and that next one (least squares on them, at least 1). With the next term in
    σ̂: a residual far above its noise, most of it one term, lets that term in, where the scatter
    of the residual itself would hold it out on a short table."""
    n = len(residual)
    from sklearn.exceptions import ConvergenceWarning  # here: importing scikit-learn takes a second or two
    from sklearn.linear_model import lars_path

    # The library holds near-collinear columns (a product beside its factors on a short table):
    # LARS dropping a degenerate one is the path working as meant, not a result to warn about.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        alphas, _, coefs = lars_path(columns, residual, method="lasso", max_iter=MAX_TERMS)
    active = np.zeros(0, int)
    for knot, alpha in enumerate(alphas):
        active = np.flatnonzero(coefs[:, knot])
        following = np.flatnonzero(coefs[:, min(knot + 1, len(alphas) - 1)])
        if alpha * n < z * _scatter(columns[:, following], residual, n - model_rank - len(following)):
            break
    return active


def _scatter(columns: np.ndarray, residual: np.ndarray, dof: int) -> float:
    """√(χ²/dof) of ``residual`` after least squares on ``columns``, at least 1."""
    left = residual - columns @ np.linalg.lstsq(columns, residual, rcond=None)[0] if columns.shape[1] else residual
    return math.sqrt(max(1.0, float(left @ left) / max(dof, 1)))


def half_samples(units: np.ndarray, resamples: int, rng: np.random.Generator) -> list[np.ndarray]:
    """Row indices of ``resamples`` half-samples of the ``units`` (each row's unit), drawn as
    complementary pairs: each pair splits the units in two halves at random."""
    labels = np.unique(units)
    half = len(labels) // 2
    found = []
    for _ in range(resamples // 2):
        order = rng.permutation(labels)
        found += [np.flatnonzero(np.isin(units, order[:half])), np.flatnonzero(np.isin(units, order[half : 2 * half]))]
    return found


def selection_frequencies(
    searched: Searched,
    residual: np.ndarray,
    jacobian: np.ndarray,
    units: np.ndarray,
    rng: np.random.Generator,
    resamples: int = RESAMPLES,
) -> np.ndarray:
    """The fraction of ``resamples`` half-samples in which the path selects each term; each
    half-sample is projected against the model's Jacobian on its own rows."""
    z = threshold(searched.unit.shape[1], SELECTION_ALPHA)
    counts = np.zeros(searched.unit.shape[1])
    samples = half_samples(units, resamples, rng)
    for done, rows in enumerate(samples):
        progress.stage("discovery (half-samples)", done, len(samples))
        basis = orthonormal_basis(jacobian[rows])
        columns = project_out(searched.weighted[rows] / searched.length, basis)
        norms = np.linalg.norm(columns, axis=0)
        columns = np.divide(columns, norms, out=np.zeros_like(columns), where=norms > RANK_RTOL)
        counts[lasso_selection(columns, project_out(residual[rows], basis), basis.shape[1], z)] += 1
    return counts / max(len(samples), 1)


# --- refit, significance, cross-validated gain -----------------------------------------------------
@dataclasses.dataclass
class Refit:
    """The joint least-squares refit of some terms (indices into the searched library)."""

    chosen: list[int]
    coefficients: np.ndarray  # per unit column
    covariance: np.ndarray  # per unit column, inflated by φ
    gain_chi2: np.ndarray  # Δχ² of each (drop-one)
    p_values: np.ndarray  # of Δχ²/φ ~ χ²(1)
    cv_gain_chi2: np.ndarray  # held-out χ² without minus with each


@dataclasses.dataclass
class Residual:
    """The weighted residual r of a fit with the model's (column-normalised) Jacobian, its rank
    and the grouped cross-validation folds: what every refit of terms works against."""

    values: np.ndarray
    jacobian: np.ndarray
    model_rank: int
    folds: list[np.ndarray]

    def scatter(self, columns: np.ndarray) -> float:
        """φ = max(1, χ²/dof) of the residual after least squares on ``columns`` beside the model."""
        left = self.values - columns @ np.linalg.lstsq(columns, self.values, rcond=None)[0]
        return max(1.0, float(left @ left) / max(len(left) - self.model_rank - columns.shape[1], 1))


def refit(searched: Searched, chosen: list[int], residual: Residual) -> Refit:
    """Strengths, σ, Δχ², p-values and cross-validated gains of the ``chosen`` terms together."""
    columns = searched.unit[:, chosen]
    coefficients = np.linalg.lstsq(columns, residual.values, rcond=None)[0]
    phi = residual.scatter(columns)
    inverse = np.linalg.pinv(columns.T @ columns)
    gain = coefficients**2 / np.diag(inverse)
    design = unit_columns(np.column_stack([residual.jacobian, searched.weighted[:, chosen]]))
    width = residual.jacobian.shape[1]
    held_out = _held_out_chi2(design, residual)
    cv_gain = [_held_out_chi2(np.delete(design, width + i, axis=1), residual) - held_out for i in range(len(chosen))]
    return Refit(chosen, coefficients, inverse * phi, gain, scipy.stats.chi2.sf(gain / phi, 1), np.array(cv_gain))


def _held_out_chi2(design: np.ndarray, residual: Residual) -> float:
    """Σ over the folds of the χ² of the fold's rows predicted by least squares of the residual on
    ``design`` over the other rows (the linearised refit without the fold)."""
    total = 0.0
    for rows in residual.folds:
        train = np.ones(len(residual.values), bool)
        train[rows] = False
        coefficients = np.linalg.lstsq(design[train], residual.values[train], rcond=None)[0]
        left = residual.values[rows] - design[rows] @ coefficients
        total += float(left @ left)
    return total


def significant(searched: Searched, chosen: list[int], residual: Residual) -> Refit:
    """The refit of the ``chosen`` terms that all pass (module docstring: Bonferroni over the
    library, positive cross-validated gain), dropping the weakest failing one at a time."""
    library_size = searched.unit.shape[1]
    while chosen:
        found = refit(searched, chosen, residual)
        failing = (found.p_values * library_size > ALPHA) | (found.cv_gain_chi2 <= 0)
        if not failing.any():
            return found
        weakest = np.flatnonzero(failing)[np.argmin(found.gain_chi2[failing])]
        chosen = [j for i, j in enumerate(chosen) if i != weakest]
    empty = np.zeros(0)
    return Refit([], empty, np.zeros((0, 0)), empty, empty, empty)


# --- plugins -------------------------------------------------------------------------------------
def plugin_name(factors: Sequence[str]) -> str:
    """A Python identifier for the effect of a term: ``discovered_`` and its factors."""
    words = [name.replace("θ0)", "theta0").replace("(", "") for name in factors]
    if len(words) == 2 and words[0] == words[1]:
        words[1] = "squared"
    return "discovered_" + "_".join(words)


def per_unit(unit: str, of: str = "Hz") -> str:
    """``of`` per ``unit``: "Hz/K", "Hz/(T·K)", "Hz" for a unit of 1."""
    return of if unit == "1" else f"{of}/({unit})" if "·" in unit else f"{of}/{unit}"


@dataclasses.dataclass(frozen=True)
class PluginForm:
    """How a plugin writes a term: its output, parameter (name, unit), the value it returns (a
    Python expression over ``rows`` and the parameter) and a first-order size per Hz of the term."""

    output: str
    parameter: str
    unit: str
    returned: str
    per_hz: float  # plugin parameter per Hz/unit of the term's strength, to first order


def factor_expression(name: str, means: dict[str, float]) -> str:
    """The physical value of a factor as a plugin computes it from ``rows``: a column, a harmonic,
    the model's rest angle or start swing, centred on the table's mean where the library centres it
    (a number, not ``rows.….mean()``: the model evaluates a plugin on a subset of rows at a time)."""
    if name.endswith("θ0)"):
        trig, k = name.split("(")
        return f"np.{trig}({k.removesuffix('θ0)')} * rows.theta0_rad)"
    if name in MODEL_FACTORS:
        return f'model_covariates(rows, PROBE)["{name}"]'
    if _factor(name).centred:
        return f"(rows.{name} - {means[name]!r})"
    return f"rows.{name}"


def product_expression(factors: Sequence[str], means: dict[str, float]) -> str:
    if len(factors) == 2 and factors[0] == factors[1]:
        return f"{factor_expression(factors[0], means)} ** 2"
    return " * ".join(factor_expression(name, means) for name in factors)


def plugin_form(factors: Sequence[str], rule: Rule, means: dict[str, float], probe: Probe) -> PluginForm:
    """The physical form of a term (module docstring), or the additive frequency term."""
    field_per_hz = 2.0 * probe.spring_nm_per_rad / (probe.f00_hz * probe.moment_am2)  # Δf = f00·m·ΔB/(2·kM)
    magnetic = [name for name in factors if _factor(name).kind in ("field", "gradient")]
    others = [name for name in factors if name not in magnetic]
    if rule.output == MOMENT and rule.family == "field_squared":
        if "b_along_t" in factors:
            return PluginForm(MOMENT, "c_per_t", "1/T", "c_per_t * rows.b_along_t", field_per_hz)
    elif rule.output == MOMENT and len(magnetic) == 1:
        lever = probe.lever_m if _factor(magnetic[0]).kind == "gradient" else 1.0
        scale = f"c * {product_expression(others, means)}" if others else "c"
        return PluginForm(MOMENT, "c", per_unit(term_unit(others), "1"), scale, field_per_hz / lever)
    if rule.output == SPRING:
        unit = per_unit(term_unit(factors), "N·m/rad")
        returned = f"k_nm_per_rad * {product_expression(factors, means)}"
        return PluginForm(SPRING, "k_nm_per_rad", unit, returned, 2.0 * probe.spring_nm_per_rad / probe.f00_hz)
    if list(factors) in (["cos(1θ0)"], ["sin(1θ0)"]):
        offset = "(b_t, 0.0)" if factors[0].startswith("cos") else "(0.0, b_t)"
        return PluginForm(FIELD, "b_t", "T", offset, field_per_hz)
    if sorted(factors) in (["b_normal_t", "cos(1θ0)"], ["b_normal_t", "sin(1θ0)"]):
        tilt = "(0.0, tilt_rad)" if any(name.startswith("cos") for name in factors) else "(tilt_rad, 0.0)"
        return PluginForm(TILT, "tilt_rad", "rad", tilt, field_per_hz)
    return frequency_form(factors, means)


def frequency_form(factors: Sequence[str], means: dict[str, float]) -> PluginForm:
    unit = per_unit(term_unit(factors))
    return PluginForm(FREQUENCY, "c_hz", unit, f"c_hz * {product_expression(factors, means)}", 1.0)


@dataclasses.dataclass(frozen=True)
class Plugin:
    """A term's plugin: its form, parameter bound and words; :meth:`source` is the file."""

    factors: tuple[str, ...]
    rule: Rule
    form: PluginForm
    bound: float
    probe: Probe
    note: str = ""

    @property
    def name(self) -> str:
        return plugin_name(self.factors)

    def imports(self) -> list[str]:
        found = ["import numpy as np"] if "np." in self.form.returned else []
        found.append("from mows.lab import effect")
        if "PROBE" in self.form.returned:
            found += _probe_source(self.probe)
        return found

    def parameters(self) -> str:
        form = self.form
        return f'{{"{form.parameter}": (0.0, {-self.bound!r}, {self.bound!r}, "{form.unit}")}}'

    def returned(self) -> str:
        return f'{{"{self.form.output}": {self.form.returned}}}'

    def source(self) -> str:
        """The plugin file."""
        reading = self.rule.reading
        why = WHY[self.form.output]
        imports = self.imports()
        found = f"the model lab's search beyond its catalog: the residual followed {term_name(self.factors)}"
        words = (
            f"{reading[0].upper() + reading[1:]}, found by {found}" if reading else f"Found by {found}"
        ) + f". Written as {self.form.output}: {why}.{self.note}"
        return "\n".join(
            [
                '"""' + textwrap.fill(words, 96, break_long_words=False, break_on_hyphens=False),
                '"""',
                "",
                *(imports[:1] + [""] + imports[1:] if imports[0].startswith("import") else imports),
                "",
                "",
                "@effect(",
                f'    name="{self.name}",',
                f"    parameters={self.parameters()},",
                f'    explanation="{reading + ": " if reading else ""}{why}",',
                f'    signature="follows {term_name(self.factors)}",',
                ")",
                f"def {self.name}(rows, {self.form.parameter}):",
                f"    return {self.returned()}",
                "",
            ]
        )

    def line(self) -> str:
        """The plugin on one line, for an explanation."""
        return (
            f'{"; ".join(self.imports())}; @effect(name="{self.name}", parameters={self.parameters()}) '
            f"def {self.name}(rows, {self.form.parameter}): return {self.returned()}"
        )


def _probe_source(probe: Probe) -> list[str]:
    """Lines that build ``PROBE`` (the analysis's probe constants) for a plugin reading the model's own θs or swing."""
    lines = ["from mows.lab.diagnosis.discovery import model_covariates", "from mows.physics.probe import Probe"]
    if isinstance(probe, ProbeSet):
        members = ", ".join(f"{i}: Probe.from_dict({member.to_dict()!r})" for i, member in probe.members)
        return lines + ["from mows.lab.data.probe_rows import ProbeSet", "", f"PROBE = ProbeSet.of({{{members}}})"]
    return lines + ["", f"PROBE = Probe.from_dict({probe.to_dict()!r})"]


def load_source(source: str, name: str) -> Effect:
    """The effect a plugin's source defines (as :func:`mows.lab.load_plugins` reads a file)."""
    namespace: dict[str, object] = {"__name__": f"mows_lab_plugin_{name}"}
    exec(compile(source, f"<{name}.py>", "exec"), namespace)  # the lab's own generated source
    return next(value for value in namespace.values() if isinstance(value, Effect))


def nice_bound(value: float) -> float:
    """The power of ten at or above ``value`` (a plugin's parameter bound)."""
    return float(10.0 ** math.ceil(math.log10(value))) if value > 0 else 1.0


def bound_for(value: float, std: float) -> float:
    """A bound ten to a hundred times a fitted value and its 3σ: room for the fit, no more."""
    return nice_bound(10.0 * (abs(value) + 3.0 * std))


# --- discover -------------------------------------------------------------------------------------
@dataclasses.dataclass
class _Search:
    """What :func:`discover` computes once and the plugins reuse."""

    fit: FitResult
    probe: Probe
    table: MeasurementTable  # the rows searched
    residual: Residual
    searched: Searched
    means: dict[str, float]
    weight: np.ndarray  # 1/σ of the rows searched


def discover(fit: FitResult, probe: Probe, seed: int = 0, plugins: bool = True) -> Discovery:
    """The terms of the rows' covariates that ``fit``'s residual follows beyond what its model
    absorbs (module docstring), each with its physical plugin (``plugins=False``: without, on
    :data:`SCREEN_RESAMPLES` half-samples, for a search that only needs the terms' stand-ins);
    ``seed`` draws the half-samples (and, for a table longer than :data:`MAX_ROWS`, the
    stratified rows searched)."""
    table = fit.table if fit.problem.rows is None else fit.table.subset(fit.problem.rows)
    if fit.invalid_rows.size or len(table) < MIN_ROWS:  # residuals of rows without a frequency are no data
        why = "the model has no frequency at some rows" if fit.invalid_rows.size else f"{len(table)} rows are too few"
        return Discovery([], 0, 0, DEGREE, f"No search beyond the catalog: {why}.", fit.model.name)
    kept = stratified_rows(table.sweep_ids, MAX_ROWS, seed)
    table = table.subset(kept) if len(kept) < len(table) else table
    jacobian = unit_columns(fit.jacobian[kept])
    model_basis = orthonormal_basis(jacobian)
    factors = factor_values(table, probe)
    searched = searchable(library(factors), fit.problem.row_weight[kept], model_basis)
    residual = Residual(fit.weighted_residual[kept], jacobian, model_basis.shape[1], cv_folds(table))
    means = factor_centres({name: table.columns[name] for name in factors if _factor(name).centred}, probe)
    search = _Search(fit, probe, table, residual, searched, means, fit.problem.row_weight[kept])
    groups = fit.problem.inverse[kept]
    units = groups if len(np.unique(groups)) >= MIN_UNITS else np.arange(len(table))
    resamples = RESAMPLES if plugins else SCREEN_RESAMPLES
    rng = np.random.default_rng(seed)
    frequencies = selection_frequencies(searched, residual.values, jacobian, units, rng, resamples)
    passed = significant(searched, [int(j) for j in np.flatnonzero(frequencies >= STABLE_FRACTION)], residual)
    terms = sorted(
        (_term(search, passed, i, frequencies, plugins) for i in range(len(passed.chosen))),
        key=lambda t: -t.cv_gain_chi2,
    )
    summary = _summary(terms, len(searched.terms)) + (
        f" (Searched on {len(table)} stratified rows of {fit.n}.)" if len(table) < fit.n else ""
    )
    stand_ins = tuple(_stand_in(term, means, probe) for term in terms)
    return Discovery(terms, len(searched.terms), resamples, DEGREE, summary, fit.model.name, stand_ins)


def _stand_in(term: DiscoveredTerm, means: dict[str, float], probe: Probe) -> Effect:
    """The term as an additive frequency effect, its strength free within its plugin's bounds."""
    form = frequency_form(term.factors, means)
    plugin = Plugin(term.factors, rule_of(term.factors), form, bound_for(term.strength, term.std), probe)
    return load_source(plugin.source(), plugin.name)


def _term(search: _Search, passed: Refit, i: int, frequencies: np.ndarray, plugins: bool) -> DiscoveredTerm:
    j = passed.chosen[i]
    term = search.searched.terms[j]
    length = search.searched.length[j]
    rule = rule_of(term.factors)
    if plugins:
        plugin, parameter = _physical_plugin(search, passed, i, rule)
    else:
        plugin, parameter = (
            Plugin(term.factors, rule, frequency_form(term.factors, search.means), 1.0, search.probe),
            None,
        )
    return DiscoveredTerm(
        term.name,
        term.factors,
        rule.family,
        float(passed.coefficients[i] / length),
        float(math.sqrt(passed.covariance[i, i]) / length),
        float(frequencies[j]),
        float(passed.cv_gain_chi2[i]),
        rule.reading,
        plugin.source(),
        term.unit,
        float(passed.p_values[i]),
        tuple(search.searched.aliases[j]),
        parameter,
        plugin.form.output,
        plugin.line(),
        _term_fit(search, passed, i),
    )


def _term_fit(search: _Search, passed: Refit, i: int) -> TermFit:
    """Term ``i`` of ``passed`` beside the residual it explains (:class:`TermFit`)."""
    j, others = passed.chosen[i], [k for k in range(len(passed.chosen)) if k != i]
    columns = search.searched.unit[:, [passed.chosen[k] for k in others]]
    explained = search.residual.values - columns @ passed.coefficients[others]
    beyond = search.searched.unit[:, j] * search.searched.length[j]
    return TermFit(beyond / search.weight, explained / search.weight, 1.0 / search.weight)


def _physical_plugin(search: _Search, passed: Refit, i: int, rule: Rule) -> tuple[Plugin, FittedParameter]:
    """The plugin of term ``i`` of ``passed`` and its parameter fitted on this table: the physical
    form where its signature reproduces the term, else the frequency term."""
    j = passed.chosen[i]
    factors = search.searched.terms[j].factors
    strength = abs(float(passed.coefficients[i])) / search.searched.length[j]
    form = plugin_form(factors, rule, search.means, search.probe)
    guess = bound_for(strength * form.per_hz, 0.0)
    plugin, column = _signature(search, Plugin(factors, rule, form, guess, search.probe))
    cosine = abs(float(column @ search.searched.unit[:, j])) / max(float(np.linalg.norm(column)), 1e-300)
    if form.output != FREQUENCY and cosine < PHYSICAL_COSINE:
        note = f" (Its physical form, {form.output}, does not reproduce it on these rows: cos {cosine:.2f}.)"
        form = frequency_form(factors, search.means)
        plugin, column = _signature(search, Plugin(factors, rule, form, bound_for(strength, 0.0), search.probe, note))
    parameter = _fitted(search, passed, i, column, form)
    bound = bound_for(parameter.value, parameter.std)
    if bound != plugin.bound:  # the first-order guess was off: the derivative again, within the final bounds
        plugin, column = _signature(search, dataclasses.replace(plugin, bound=bound))
        parameter = _fitted(search, passed, i, column, form)
    return plugin, parameter


def _signature(search: _Search, plugin: Plugin) -> tuple[Plugin, np.ndarray]:
    """(the plugin, its signature): d(weighted residual)/d(parameter) beside the model at 0, projected."""
    effect = load_source(plugin.source(), plugin.name)
    column = search.fit.extension_columns(effect, search.table)[:, 0]
    return plugin, project_out(column[:, None], orthonormal_basis(search.residual.jacobian))[:, 0]


def _fitted(search: _Search, passed: Refit, i: int, column: np.ndarray, form: PluginForm) -> FittedParameter:
    """The plugin's parameter by least squares of the residual on its signature beside the other
    terms, σ inflated by the scatter they leave."""
    design = np.column_stack([column, np.delete(search.searched.unit[:, passed.chosen], i, axis=1)])
    coefficients = np.linalg.lstsq(design, search.residual.values, rcond=None)[0]
    variance = np.linalg.pinv(design.T @ design)[0, 0] * search.residual.scatter(design)
    # The signature is d(weighted residual)/dp = −w·df/dp: the parameter is minus the coefficient.
    return FittedParameter(form.parameter, -float(coefficients[0]), math.sqrt(variance), form.unit)


def _summary(terms: list[DiscoveredTerm], library_size: int) -> str:
    how = (
        f"A sparse search of {library_size} terms (the rows' covariates, their products and squares up to degree "
        f"{DEGREE}, each beyond what the model absorbs; kept when selected in ≥ {100 * STABLE_FRACTION:.0f}% of "
        f"{RESAMPLES} half-samples, significant after Bonferroni and cross-validated)"
    )
    if not terms:
        return how + " finds no term."
    listed = "; ".join(term.text() for term in terms)
    return f"{how} finds {len(terms)} term{'s' if len(terms) > 1 else ''}: {listed}."
