"""One model's weighted least-squares problem on one table, and the fitted result.

:class:`Problem` gives the weighted residuals and their Jacobian (f00's column exact, the
effect parameters' by forward differences); :class:`FitResult` is what
:meth:`mows.lab.model.frequency_model.FrequencyModel.fit` returns: values, covariance (Birge-inflated), χ², BIC,
identifiability, cross-validation and the report. The model and the method are described in
:mod:`mows.lab.model.frequency_model`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any

import numpy as np

from mows.estimate.ringdown import FitStatus
from mows.lab import progress
from mows.lab.data.folds import cv_folds
from mows.lab.data.table import MeasurementTable, rows_text
from mows.lab.model.effects import Effect

if TYPE_CHECKING:  # frequency_model imports this module
    from mows.lab.model.frequency_model import FrequencyModel

FD_STEP = 1e-2  # × parameter scale
INVALID_RESIDUAL = 1e6  # weighted residual given to rows where the model has no real frequency
DEGENERATE_RTOL = 1e-6  # singular value (normalised Jacobian columns) below which a direction is not determined
CV_PREDICTION_SIGMAS = 10.0  # a fold predicting its rows less precisely than this says nothing
DEGENERATE_WEIGHT = 0.1  # a parameter with more than this weight in such a direction is not identifiable


@dataclasses.dataclass(frozen=True)
class FittedParameter:
    """One fitted parameter, like lmfit's ``Parameter``: its value and standard error σ in
    ``unit``. (:class:`mows.lab.model.effects.Parameter` declares a parameter's bounds before
    any fit; this is what a fit found.)"""

    name: str
    value: float
    std: float
    unit: str

    def text(self) -> str:
        """``name = value ± σ unit``, as the reports print it."""
        return f"{self.name} = {self.value:.4g} ± {self.std:.2g} {self.unit}".rstrip()

    def to_dict(self) -> dict[str, float | str]:
        return {"value": self.value, "std": self.std, "unit": self.unit}


def parameters_dict(parameters: Iterable[FittedParameter]) -> dict[str, dict[str, float | str]]:
    """The JSON form of fitted parameters: {name: {value, std, unit}}."""
    return {p.name: p.to_dict() for p in parameters}


def parameter_values(parameters: Iterable[FittedParameter]) -> dict[str, float]:
    """{name: value} of fitted parameters."""
    return {p.name: p.value for p in parameters}


class Problem:
    """Weighted residuals and their Jacobian for one model on the ``rows`` of one table (default:
    every row), with a one-point cache (scipy asks for the Jacobian at the point whose residual
    it has just computed).

    The model gives every row of a configuration group (:meth:`FrequencyModel.groups`) the same
    frequency m_g, so the fit works on the groups' exact sufficient statistics: the weight
    W_g = Σ 1/σ_i², the weighted mean f̄_g = Σ f_i/σ_i² / W_g and the within-group
    χ²_w = Σ ((f_i − f̄_g)/σ_i)². Since Σ ((f_i − m_g)/σ_i)² = W_g·(f̄_g − m_g)² + that group's
    share of χ²_w, the residuals r_g = √W_g·(f̄_g − m_g) give χ² = Σ r_g² + χ²_w, and their
    Jacobian −√W_g·∂m_g/∂x gives JᵀJ, of every row: the same parameters, σ and BIC, at a
    cost that grows with the groups. Where an effect reads a column that differs on every row
    (time, temperature), each row is its own group and this is the row-by-row problem.
    """

    def __init__(self, model: FrequencyModel, table: MeasurementTable, rows: np.ndarray | None = None) -> None:
        self.model, self.table = model, table
        self.distinct, inverse = model.groups(table)
        self.rows = rows
        self.inverse = inverse if rows is None else inverse[rows]
        self.group_f00 = model.probe_index(self.distinct)  # each group's f00 (one per probe)
        f_hz, w2, groups = self.of_rows(table.f_hz), self.row_weight**2, len(self.distinct)
        self.count = np.bincount(self.inverse, minlength=groups)
        weight = np.bincount(self.inverse, w2, groups)
        self.root_weight = np.sqrt(weight)
        self.mean_hz = np.bincount(self.inverse, w2 * f_hz, groups) / np.where(self.count > 0, weight, 1.0)
        self.within_chi2 = float(np.sum(w2 * (f_hz - self.mean_hz[self.inverse]) ** 2))
        self.steps = np.array([FD_STEP * p.scale for _, p in model.parameters])
        self.upper = np.array([p.upper for _, p in model.parameters])
        self._cache: tuple[bytes | None, Any] = (None, None)

    def of_rows(self, values: np.ndarray) -> np.ndarray:
        return values if self.rows is None else values[self.rows]

    @property
    def n(self) -> int:
        return len(self.inverse)

    @property
    def row_weight(self) -> np.ndarray:
        """1/σ of each row (computed when asked: every fit keeps its problem)."""
        return 1.0 / self.of_rows(self.table.f_std_hz)

    def factors(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(h, c) of each group at effect parameter values ``p``."""
        key = p.tobytes()
        if self._cache[0] != key:
            self._cache = (key, self.model.group_factors(self.distinct, p))
            progress.evaluated()
        return self._cache[1]

    @property
    def f00_count(self) -> int:
        return self.model.f00_count

    def best_f00(self, p: np.ndarray) -> np.ndarray:
        """Each probe's f00 in closed form at effect parameters ``p`` (f00 enters linearly)."""
        h, c = self.factors(np.asarray(p, float))
        w2 = self.root_weight**2
        good = np.isfinite(h)
        return np.array(
            [
                np.sum((w2 * h * (self.mean_hz - c))[own]) / np.sum((w2 * h * h)[own])
                for own in (good & (self.group_f00 == k) for k in range(self.f00_count))
            ]
        )

    def model_hz(self, x: np.ndarray) -> np.ndarray:
        """m_g of each group at ``x`` = [f00 (one per probe), effect parameters…] (NaN where it
        has no real frequency)."""
        h, c = self.factors(x[self.f00_count :])
        return x[: self.f00_count][self.group_f00] * h + c

    def residual(self, x: np.ndarray) -> np.ndarray:
        """r_g = √W_g·(f̄_g − m_g); a group without a real frequency gets INVALID_RESIDUAL per row."""
        r = self.root_weight * (self.mean_hz - self.model_hz(x))
        return np.where(np.isfinite(r), r, INVALID_RESIDUAL * np.sqrt(self.count))

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        """d(r_g)/d(x), (groups, k)."""
        return -self.root_weight[:, None] * self.derivative(x, range(len(x)))

    def derivative(self, x: np.ndarray, indices: Iterable[int]) -> np.ndarray:
        """dm_g/dx_j for j in ``indices`` (f00s: exact; effect parameters: forward differences),
        (groups, len(indices)); 0 where the model has no real frequency."""
        first = self.f00_count
        h, _ = self.factors(x[first:])
        base = self.model_hz(x)
        columns = []
        for j in indices:
            if j < first:
                columns.append(h * (self.group_f00 == j))
                continue
            p = x[first:].copy()
            i = j - first
            # Step inwards at an upper bound, so that the model is evaluated where it is defined.
            step = -self.steps[i] if p[i] + self.steps[i] > self.upper[i] else self.steps[i]
            p[i] += step
            columns.append((self.model_hz(np.concatenate([x[:first], p])) - base) / step)
        found = np.stack(columns, -1) if columns else np.zeros((len(base), 0))
        return np.where(np.isfinite(found), found, 0.0)

    def columns(self, x: np.ndarray, indices: Iterable[int]) -> np.ndarray:
        """d(weighted residual of each row)/d(x_j), j in ``indices``: (rows, len(indices))."""
        return -self.row_weight[:, None] * self.derivative(x, indices)[self.inverse]

    def result(self, x: np.ndarray, success: bool, message: str) -> FitResult:
        residual = self.residual(x)
        jacobian = self.jacobian(x)
        chi2 = float(residual @ residual) + self.within_chi2
        n, k = self.n, len(x)
        u, s, vt = np.linalg.svd(jacobian, full_matrices=False)
        keep = s > s[0] * 1e-10
        covariance = (vt[keep].T / s[keep] ** 2) @ vt[keep]
        birge = max(1.0, chi2 / max(n - k, 1))
        return FitResult(
            self.model,
            self,
            np.asarray(x, float),
            covariance * birge,
            chi2,
            n,
            k,
            self.model_hz(x),
            jacobian,
            bool(success),
            str(message),
        )


@dataclasses.dataclass(eq=False)
class FitResult:
    """A fitted :class:`mows.lab.model.frequency_model.FrequencyModel`. ``values``/``covariance`` are ordered as
    ``model.parameter_names``. ``group_model_hz`` and ``group_jacobian`` are the model's
    frequency and the Jacobian of the fit's residuals per configuration group (:class:`Problem`);
    the per-row ``prediction_hz``, ``weighted_residual`` and ``jacobian`` (d(weighted
    residual)/d(values), (n, k)) follow from them on the fitted rows.

    The result protocol shared with the ring-down fit (:class:`mows.estimate.ringdown.RingdownFit`):
    ``status`` (a :class:`~mows.estimate.ringdown.FitStatus`, compared by name), ``ok`` and
    ``report()``; ``message`` says why when the status is not OK.
    """

    model: FrequencyModel
    problem: Problem
    values: np.ndarray
    covariance: np.ndarray
    chi2: float
    n: int
    k: int
    group_model_hz: np.ndarray
    group_jacobian: np.ndarray
    success: bool
    message: str

    @property
    def table(self) -> MeasurementTable:
        return self.problem.table

    @property
    def prediction_hz(self) -> np.ndarray:
        """The model's frequency at each fitted row (NaN where it has none)."""
        return self.group_model_hz[self.problem.inverse]

    @property
    def jacobian(self) -> np.ndarray:
        """d(weighted residual of each fitted row)/d(values), (n, k)."""
        root_weight = self.problem.root_weight[:, None]
        per_weight = np.divide(
            self.group_jacobian, root_weight, out=np.zeros_like(self.group_jacobian), where=root_weight > 0
        )
        return self.problem.row_weight[:, None] * per_weight[self.problem.inverse]

    @property
    def status(self) -> FitStatus:
        """OK; BAD_FIT when the model has no real frequency at some rows (:attr:`invalid_rows`:
        their residuals are a penalty, not data, so χ² means nothing); NOT_CONVERGED when the
        optimiser stopped before its tolerances were met."""
        if self.invalid_rows.size:
            return FitStatus.BAD_FIT
        return FitStatus.OK if self.success else FitStatus.NOT_CONVERGED

    @property
    def identifiable(self) -> np.ndarray:
        """Per parameter (order of ``values``): False when this table cannot determine it: its
        Jacobian column is zero, or it takes part (weight > 0.1) in a direction the normalised
        Jacobian does not determine (singular value < 1e-6 of the largest: exact aliases such as
        gravity and an unreferenced field), or its σ exceeds its whole physical range."""
        jacobian = self.group_jacobian  # the rows' Jacobian has the same JᵀJ (Problem)
        norms = np.linalg.norm(jacobian, axis=0)
        found = norms > 0
        if found.any():
            _, s, vt = np.linalg.svd(jacobian[:, found] / norms[found], full_matrices=False)
            undetermined = vt[s < DEGENERATE_RTOL * s[0]]
            found[found] = np.all(np.abs(undetermined) <= DEGENERATE_WEIGHT, axis=0)
        ranges = np.array([np.inf] * self.model.f00_count + [p.upper - p.lower for _, p in self.model.parameters])
        return found & (self.std < ranges)

    @property
    def invalid_rows(self) -> np.ndarray:
        """Indices of the rows where the model has no real frequency at the fitted values."""
        return np.flatnonzero(~np.isfinite(self.prediction_hz))

    @property
    def ok(self) -> bool:
        return self.status is FitStatus.OK

    @property
    def dof(self) -> int:
        return self.n - self.k

    @property
    def chi2_dof(self) -> float:
        return self.chi2 / self.dof if self.dof > 0 else math.nan

    @property
    def bic(self) -> float:
        return self.chi2 + self.k * math.log(self.n)

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def residual_hz(self) -> np.ndarray:
        return self.problem.of_rows(self.table.f_hz) - self.prediction_hz

    @property
    def weighted_residual(self) -> np.ndarray:
        return self.residual_hz * self.problem.row_weight

    @property
    def effect_values(self) -> np.ndarray:
        """The fitted effect parameters, without the f00s (fit order)."""
        return self.values[self.model.f00_count :]

    @property
    def row_f00_hz(self) -> np.ndarray:
        """The fitted f00 of each row's probe, over the whole table, Hz."""
        return self.values[: self.model.f00_count][self.model.probe_index(self.table)]

    def parameters(self) -> list[FittedParameter]:
        """The f00s and every effect parameter, named ``effect.parameter``, in fit order."""
        units = ["Hz"] * self.model.f00_count + [p.unit for _, p in self.model.parameters]
        columns = zip(self.model.parameter_names, self.values.tolist(), self.std.tolist(), units)
        return [FittedParameter(*column) for column in columns]

    def values_without(self, effect: Effect) -> np.ndarray:
        """The fitted effect parameter values (fit order) of the model without ``effect``: a
        start for fitting ``model.without(effect)``."""
        keep = [e is not effect for e in self.model.effects for _ in e.parameters]
        return self.effect_values[np.array(keep, bool)]

    def effect_parameters(self, effect_name: str) -> list[FittedParameter]:
        """The parameters of one effect of the model, named without the effect's prefix."""
        prefix = effect_name + "."
        return [
            dataclasses.replace(p, name=p.name.removeprefix(prefix))
            for p in self.parameters()
            if p.name.startswith(prefix)
        ]

    def extension_columns(self, effect: Effect, table: MeasurementTable | None = None) -> np.ndarray:
        """d(weighted residual)/d(parameters of ``effect``) with ``effect`` added to this model at
        its off values and the other parameters at their fitted values: the candidate's signature.
        On ``table`` (default: the fitted table; e.g. a what-if variant of it)."""
        extended = self.model + effect
        x = np.concatenate([self.values, effect.off_values])
        first = len(self.model.parameters) + self.model.f00_count
        return Problem(extended, self.table if table is None else table).columns(
            x, range(first, first + len(effect.parameters))
        )

    def prediction_sigmas(self, table: MeasurementTable, rows: np.ndarray | None = None) -> float:
        """Median over ``table``'s ``rows`` (default: all) of this fit's prediction uncertainty
        there, in units of each row's ``f_std_hz``: from the parameter covariance without the
        Birge inflation, so that it measures what the fitted rows say about these, not how well
        the model fits."""
        jacobian = self.model_jacobian(table, rows)
        variance = np.einsum("ni,ij,nj->n", jacobian, self.covariance, jacobian) / max(1.0, self.chi2_dof)
        return float(np.median(np.sqrt(variance)))

    def model_jacobian(self, table: MeasurementTable, rows: np.ndarray | None = None) -> np.ndarray:
        """d(weighted residual)/d(values) of this model at the fitted values on ``table``'s
        ``rows`` (default: all), (rows, k)."""
        return Problem(self.model, table, rows).columns(self.values, range(self.k))

    @functools.cached_property
    def held_out_chi2(self) -> float:
        """χ² of every row as predicted by the fit without its fold (:func:`mows.lab.data.folds.cv_folds`:
        whole sweeps, current steps or temperature spans), to first order in the parameters:
        each fold's refit is one Gauss–Newton step from this fit, δ = −(J₋ᵀJ₋)⁺·J₋ᵀr₋ over the
        other rows, which is exact for parameters that enter linearly (f00, the blended
        strengths) and costs no evaluation of the model. It is how the search asks whether an
        effect generalises: one that only fits the structure of some configurations predicts the
        others worse. Infinite when a fold held the only information on a parameter."""
        jacobian, residual = self.jacobian, self.weighted_residual
        scale = np.linalg.norm(jacobian, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        unit = jacobian / scale
        rank = np.linalg.matrix_rank(unit, rtol=DEGENERATE_RTOL)
        total = 0.0
        for rows in cv_folds(self.table):
            kept = np.ones(self.n, bool)
            kept[rows] = False
            if np.linalg.matrix_rank(unit[kept], rtol=DEGENERATE_RTOL) < rank:
                return math.inf
            step = np.linalg.lstsq(unit[kept], -residual[kept], rcond=DEGENERATE_RTOL)[0]
            predicted = residual[rows] + unit[rows] @ step
            total += float(predicted @ predicted)
        return total

    def cross_validate(self) -> float:
        """Cross-validated rms prediction error, Hz: K-fold over the rows' configurations (whole
        sweeps, current steps or temperature spans: :func:`mows.lab.data.folds.cv_folds`): refit
        without the fold, predict it. NaN when it
        is not identifiable: a left-out fold held the only information on a parameter (the fit
        without it cannot determine a parameter the whole table determines, or predicts the
        left-out rows with a median uncertainty above 10 σ of their measurements)."""
        folds = cv_folds(self.table)
        errors = np.empty(self.n)
        for done, rows in enumerate(folds):
            progress.stage("cross-validation (folds)", done, len(folds))
            train = np.ones(self.n, bool)
            train[rows] = False
            part = self.model.fit(self.table, start=self.effect_values, rows=np.flatnonzero(train))
            if (
                np.any(self.identifiable & ~part.identifiable)
                or part.prediction_sigmas(self.table, rows) > CV_PREDICTION_SIGMAS
            ):
                return math.nan
            errors[rows] = self.table.f_hz[rows] - part.problem.model_hz(part.values)[self.problem.inverse[rows]]
        return float(np.sqrt(np.mean(errors**2)))

    def report(self) -> str:
        quality = (
            f"χ²/dof = {self.chi2_dof:.3f}, BIC = {self.bic:.1f}"
            if self.status is not FitStatus.BAD_FIT
            else "χ² not meaningful"
        )
        lines = [f"model {self.model.name}: n = {self.n}, {quality}"]
        for p, known in zip(self.parameters(), self.identifiable):
            lines.append(
                f"  {p.name:40s} = {p.value:+.6g} ± {p.std:.2g} {p.unit}"
                if known
                else f"  {p.name:40s}   not identifiable from this table"
            )
        if self.status is FitStatus.BAD_FIT:
            lines.append(
                f"  warning: {self.status.name}: the model has no real frequency at "
                f"{rows_text(self.invalid_rows)} (mows.lab.model.factors.unevaluable_rows says why)"
            )
        elif not self.ok:
            lines.append(f"  warning: {self.status.name}: the fit did not converge ({self.message})")
        return "\n".join(lines)
