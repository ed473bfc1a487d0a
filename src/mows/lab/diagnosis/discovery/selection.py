"""The sparse search over the library of channel terms: which terms the residual follows.

**What is searched.** Each term's weighted column (a channel's Jacobian times a monomial,
:mod:`.channels`) is projected orthogonally to the current fit's Jacobian
(:mod:`mows.lab.diagnosis.projections`: only what the model's free parameters cannot absorb), and
scaled to unit length; the target is the weighted residual r = (f − model)/σ. Terms the model
absorbs (left with < 1e-3 of their length) are dropped, and of terms the rows cannot tell apart
(|cos| ≥ 0.999) the first in library order is kept and the others are its ``aliases``.

**Sparse regression.** The lasso path by LARS (scikit-learn's ``lars_path``), stopped by the
noise: the next term enters only while its correlation with the residual exceeds the Bonferroni
threshold over the library times the residual scatter of the terms already in (at least 1, the
stated σ). This is the scaled lasso's rule on the path: a penalty at the noise level, with the
noise estimated from what the terms leave, so that a residual 100× its noise still lets its
leading term in and not the ones the leading term explains. It is scikit-learn, not PySINDy: the
problem is a static regression of residuals on covariates, not the identification of dynamics
x' = Θ(x)·ξ that PySINDy is built for, and LARS gives the whole path for one least-squares solve.

**Stability selection.** The path runs on half-samples (complementary pairs, seeded) of the
current model's configuration groups, each re-projected against the model's Jacobian on its rows.
A term is kept when it is selected in at least :data:`STABLE_FRACTION` of them.
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np
import scipy.stats

from mows.lab import progress
from mows.lab.diagnosis.discovery.channels import Channel
from mows.lab.diagnosis.discovery.library import term_name, term_unit
from mows.lab.diagnosis.projections import RANK_RTOL, SPAN_COSINE, orthonormal_basis, project_out

RESAMPLES = 100  # half-samples of the stability selection (50 complementary pairs)
STABLE_FRACTION = 0.8  # a term is kept when selected in at least this fraction of them
SELECTION_ALPHA = 0.05  # family-wise level over the library of one half-sample's path
MAX_TERMS = 6  # steps of one path: a sparse answer has a few terms


@dataclasses.dataclass
class Term:
    """A library term: a channel times a monomial (its factors), and its weighted column."""

    channel: Channel
    factors: tuple[str, ...]
    weighted: np.ndarray  # (n,) w·∂f/∂p·x: the frequency change per unit of the term's parameter

    @property
    def name(self) -> str:
        """``channel × monomial``, e.g. ``moment × temperature_k``, ``spring × coil_current_a²``."""
        return f"{self.channel.name} × {term_name(self.factors)}"

    @property
    def unit(self) -> str:
        """The unit of the monomial."""
        return term_unit(self.factors)


@dataclasses.dataclass
class Searched:
    """The library as searched: the terms kept, their weighted columns (unprojected) and projected
    unit columns, the projected length of each (per unit of the term's parameter), each kept
    term's aliases, and the projected unit columns of every term not absorbed (for the readings
    that fit as well: :func:`mows.lab.diagnosis.discovery.readings.alternatives`)."""

    terms: list[Term]
    weighted: np.ndarray  # (n, L)
    unit: np.ndarray  # (n, L) P⊥ of those, unit length
    length: np.ndarray  # (L,)
    aliases: list[list[str]]
    every: list[Term]  # every term the model does not absorb
    every_unit: np.ndarray  # (n, len(every))


def searchable(terms: list[Term], model_basis: np.ndarray) -> Searched:
    """Project every term orthogonally to the model, drop those it absorbs, keep the first of
    terms the rows cannot tell apart (module docstring)."""
    weighted = np.column_stack([t.weighted for t in terms])
    before = np.linalg.norm(weighted, axis=0)
    projected = project_out(weighted, model_basis)
    length = np.linalg.norm(projected, axis=0)
    free = np.flatnonzero((before > 0) & (length > RANK_RTOL * before))
    unit = projected[:, free] / length[free]
    kept: list[int] = []
    aliases: dict[int, list[str]] = {}
    for j in range(len(free)):
        twins = np.flatnonzero(np.abs(unit[:, kept].T @ unit[:, j]) >= SPAN_COSINE) if kept else np.zeros(0, int)
        if len(twins):
            aliases[kept[int(twins[0])]].append(terms[free[j]].name)
        else:
            kept.append(j)
            aliases[j] = []
    chosen = free[kept]
    return Searched(
        [terms[i] for i in chosen],
        weighted[:, chosen],
        unit[:, kept],
        length[chosen],
        [aliases[j] for j in kept],
        [terms[i] for i in free],
        unit,
    )


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
