"""Residual structure of a fit: harmonics of θ0 and covariate trends the model does not absorb.

Harmonics k = 0…4 of θ0 (columns cos kθ0/σ, sin kθ0/σ) and each covariate (column c/σ) are
projected orthogonally to the fit (:mod:`mows.lab.diagnosis.projections`) and score-tested against the
residual; amplitudes come from the projected least squares, where the projected columns have full rank
(else the angles leave the harmonic's amplitude and phase undetermined: "not identifiable from
these angles", while its score test still counts). Significant means p < 0.005 after
Bonferroni over all these tests. ``goodness_p`` is the χ² test of the whole fit.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import scipy.stats

from mows.lab.diagnosis.projections import Signature, orthonormal_basis, signature
from mows.lab.model.least_squares import FitResult
from mows.records.json_numbers import finite_or_none

HARMONICS = range(5)
STRUCTURE_ALPHA = 0.005  # family-wise, Bonferroni over harmonics and covariates
GOODNESS_ALPHA = 0.005  # with STRUCTURE_ALPHA: ≈ 1 % false alarms for a complete model


@dataclasses.dataclass
class Harmonic:
    k: int
    amplitude_hz: float
    std_hz: float
    phase_rad: float
    p_value: float
    absorbed: bool
    identifiable: bool = True  # False: the angles leave amplitude and phase undetermined (NaN)

    def to_dict(self) -> dict:
        return finite_or_none(dataclasses.asdict(self))

    def text(self) -> str:
        """Amplitude ± σ and phase, or why there are none."""
        if self.absorbed:
            return "absorbed by the model"
        if not self.identifiable:
            return "not identifiable from these angles"
        return f"{self.amplitude_hz * 1e3:.3g} ± {self.std_hz * 1e3:.2g} mHz, phase {math.degrees(self.phase_rad):.0f}°"


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
    harmonics: list[Harmonic]
    covariates: list[CovariateTrend]
    alpha: float
    summary: str = ""

    @property
    def significant(self) -> list[str]:
        """Descriptions of the significant features."""
        found = [
            f"harmonic {h.k} of θ0 ({h.text()}, p = {h.p_value:.1e})"
            for h in self.harmonics
            if not h.absorbed and h.p_value < self.alpha
        ]
        found += [
            f"a trend with {c.name} (correlation {c.correlation:+.2f}, p = {c.p_value:.1e})"
            for c in self.covariates
            if c.p_value < self.alpha
        ]
        return found

    def to_dict(self) -> dict:
        return {
            "summary": self.summary,
            "chi2": self.chi2,
            "dof": self.dof,
            "goodness_p": self.goodness_p,
            "alpha": self.alpha,
            "harmonics": [h.to_dict() for h in self.harmonics],
            "covariates": [dataclasses.asdict(c) for c in self.covariates],
        }


def residual_structure(fit: FitResult) -> Structure:
    """Harmonics 0–4 and covariate trends of the fit's residual (module docstring)."""
    residual = fit.weighted_residual
    weight = 1.0 / fit.table.f_std_hz
    model_basis = orthonormal_basis(fit.jacobian)
    theta = fit.table.theta0_rad
    harmonics = []
    for k in HARMONICS:
        columns = np.column_stack([np.cos(k * theta), np.sin(k * theta)] if k else [np.ones_like(theta)])
        columns = columns * weight[:, None]
        harmonics.append(_harmonic(k, signature(columns, model_basis, residual), residual))
    trends = []
    for name, values in fit.table.covariates().items():
        test = signature((values - values.mean()) * weight, model_basis, residual)
        if test.rank:
            direction = test.projected[:, 0]
            trends.append(
                CovariateTrend(
                    name,
                    float(direction @ residual / (np.linalg.norm(direction) * np.linalg.norm(residual))),
                    float(direction @ residual / (direction @ direction)),
                    test.p_value,
                )
            )
    tests = sum(not h.absorbed for h in harmonics) + len(trends)
    structure = Structure(
        fit.chi2,
        fit.dof,
        float(scipy.stats.chi2.sf(fit.chi2, max(fit.dof, 1))),
        harmonics,
        trends,
        STRUCTURE_ALPHA / max(tests, 1),
    )
    structure.summary = _describe(structure)
    return structure


def _harmonic(k: int, test: Signature, residual: np.ndarray) -> Harmonic:
    if not test.rank:
        return Harmonic(k, 0.0, 0.0, 0.0, 1.0, True)
    if test.rank < test.projected.shape[1]:  # e.g. two orientations: cos kθ0 and sin kθ0 not separable
        return Harmonic(k, math.nan, math.nan, math.nan, test.p_value, False, identifiable=False)
    coefficients, *_ = np.linalg.lstsq(test.projected, residual, rcond=None)
    covariance = np.linalg.pinv(test.projected.T @ test.projected)
    c, s = (coefficients[0], coefficients[1]) if k else (coefficients[0], 0.0)
    amplitude = math.hypot(c, s)
    gradient = np.array([c, s])[: len(coefficients)] / amplitude if amplitude > 0 else np.ones(len(coefficients))
    std = float(np.sqrt(gradient @ covariance @ gradient))
    return Harmonic(k, amplitude, std, math.atan2(-s, c), test.p_value, False)


def _describe(structure: Structure) -> str:
    reduced = structure.chi2 / max(structure.dof, 1)
    head = f"χ²/dof = {reduced:.3g} over {structure.dof} degrees of freedom (p = {structure.goodness_p:.2g}): " + (
        "consistent with the stated uncertainties"
        if structure.goodness_p >= GOODNESS_ALPHA
        else "the residuals exceed the stated uncertainties"
    )
    found = structure.significant
    if found:
        return head + ". Significant structure: " + "; ".join(found) + "."
    if structure.goodness_p < GOODNESS_ALPHA:
        return (
            head + ". No harmonic of θ0 up to 4 and no covariate trend stands out: the excess looks "
            f"like white scatter (f_std_hz ≈ ×{math.sqrt(reduced):.2f} too small, or noise the "
            "model does not describe)."
        )
    return head + ". No significant structure: the residuals look like noise."


def product_trends(fit: FitResult, count: int = 3) -> list[CovariateTrend]:
    """The ``count`` strongest trends of the residual with products of two factors (each
    centred), best first: what a missing effect that no single covariate shows may follow
    (a drift that grows with the current, a field term that changes with temperature, an
    angle pattern cos kθ0 or sin kθ0, k = 1…4, that changes with time). Not part of the
    significance tests above; a pointer for the user's own effect (:func:`plugin_expression`)."""
    residual = fit.weighted_residual
    weight = 1.0 / fit.table.f_std_hz
    model_basis = orthonormal_basis(fit.jacobian)
    covariates = {name: values - values.mean() for name, values in fit.table.covariates().items()}
    theta0 = fit.table.theta0_rad
    angles = {f"{trig}({k}θ0)": getattr(np, trig)(k * theta0) for k in HARMONICS[1:] for trig in ("cos", "sin")}
    names = list(covariates)
    pairs = [(a, covariates[a], b, covariates[b]) for i, a in enumerate(names) for b in names[i + 1 :]]
    pairs += [(a, angle, b, covariates[b]) for a, angle in angles.items() for b in names]
    found = []
    for a, first, b, second in pairs:
        product = first * second
        test = signature((product - product.mean()) * weight, model_basis, residual)
        if test.rank:
            direction = test.projected[:, 0]
            found.append(
                CovariateTrend(
                    f"{a}·{b}",
                    float(direction @ residual / (np.linalg.norm(direction) * np.linalg.norm(residual))),
                    float(direction @ residual / (direction @ direction)),
                    test.p_value,
                )
            )
    return sorted(found, key=lambda trend: -abs(trend.correlation))[:count]


def plugin_expression(factor: str) -> str:
    """A plugin's numpy expression (over ``rows``) for one factor of a trend's name: an angle
    harmonic ``cos(3θ0)`` or a centred, scaled covariate."""
    if factor.endswith("θ0)"):
        trig, k = factor.split("(")
        return f"np.{trig}({k.removesuffix('θ0)')} * rows.theta0_rad)"
    return f"(rows.{factor} - rows.{factor}.mean()) / rows.{factor}.std()"
