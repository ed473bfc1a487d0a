"""The search beyond the catalog, end to end: the library of channel terms on the rows searched,
the stability selection, the refit, and each term found with its reading and plugin.

A table longer than :data:`MAX_ROWS` is searched on that many stratified rows
(:func:`mows.lab.data.table.stratified_rows`: whole sweeps spread over the table), so that the
search stays within a fraction of a second and tens of megabytes. Half-samples are drawn over the
current model's configuration groups (rows the model cannot tell apart; the rows themselves when
there are fewer than :data:`MIN_UNITS` groups).

Each term's plugin (:mod:`.plugin_source`) has its parameter fitted on the same projected residual
through the plugin's own signature (:meth:`FitResult.extension_columns`); the signature of a
channel term is its column, so the two agree, and where they do not (|cos| <
:data:`PHYSICAL_COSINE`), or the plugin interface has no output for the channel, the plugin is the
additive frequency term closest to it, and the term says why.

Of the readings the rows cannot tell apart, the simplest is reported (:func:`simplest`: the lowest
degree of the monomial), and the others are listed beside it with the measurement that would tell
them apart (:func:`mows.lab.diagnosis.discovery.readings.alternatives`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.lab.data.folds import cv_folds
from mows.lab.data.probe_rows import ProbeSet
from mows.lab.data.table import MeasurementTable, stratified_rows
from mows.lab.diagnosis.discovery import readings
from mows.lab.diagnosis.discovery.channels import CHANNELS, FREQUENCY, jacobians
from mows.lab.diagnosis.discovery.found import DiscoveredTerm, Discovery, TermFit, summary
from mows.lab.diagnosis.discovery.library import (
    DEGREE,
    factor,
    factor_centres,
    factor_values,
    monomial_values,
    monomials,
)
from mows.lab.diagnosis.discovery.plugin_source import Plugin, bound_for, load_source, writable
from mows.lab.diagnosis.discovery.refit import Refit, Residual, significant
from mows.lab.diagnosis.discovery.selection import (
    RESAMPLES,
    STABLE_FRACTION,
    Searched,
    Term,
    searchable,
    selection_frequencies,
)
from mows.lab.diagnosis.projections import orthonormal_basis, project_out, unit_columns
from mows.lab.model.effects import Effect
from mows.lab.model.least_squares import FitResult, FittedParameter

SCREEN_RESAMPLES = 40  # … for the search's stand-ins (plugins=False), a screen that reports nothing
MIN_UNITS = 8  # fewer configuration groups than this: half-samples of rows
MIN_ROWS = 12  # fewer rows than this say nothing on a library of terms
MAX_ROWS = 4_000  # a longer table is searched on this many stratified rows (whole sweeps first)
PHYSICAL_COSINE = 0.95  # a plugin's signature at least this close to the term's writes it


def library_terms(factors: dict[str, np.ndarray], jacobian: dict[str, np.ndarray], weight: np.ndarray) -> list[Term]:
    """Every channel of ``jacobian`` times its monomials (:mod:`.library`), in library order: the
    physical channels' columns w·∂f/∂p·x, the frequency's w·(x − x̄) (f00 takes a constant)."""
    n = len(weight)
    found = []
    for channel in (channel for channel in CHANNELS if channel.name in jacobian):
        for chosen in monomials(factors, channel.excludes):
            values = monomial_values(factors, chosen, n)
            column = weight * (values - values.mean()) if channel is FREQUENCY else jacobian[channel.name] * values
            found.append(Term(channel, chosen, column))
    # Of terms the rows cannot tell apart the first is kept: the lowest degree first (an angle
    # that follows T before a field along the lever that follows B⊥·T), then the channels' order.
    return sorted(found, key=lambda term: len(term.factors))


def simplest(searched: Searched, passed: Refit) -> list[int]:
    """The terms of ``passed``, each replaced by the first term in library order (the lowest
    degree, then the channels' order) that the rows cannot tell from it: swapping them changes χ²
    by less than :data:`mows.lab.diagnosis.discovery.readings.DISTINGUISH_CHI2`. A physical
    channel is never replaced by the additive frequency."""
    chosen = list(passed.chosen)
    physical = np.array([term.channel is not FREQUENCY for term in searched.terms])
    for i, j in enumerate(passed.chosen):
        cosine = np.abs(searched.unit.T @ searched.unit[:, j])
        close = passed.gain_chi2[i] * (1.0 - cosine**2) <= readings.DISTINGUISH_CHI2
        close &= physical | (not physical[j])
        candidates = [int(k) for k in np.flatnonzero(close[:j]) if k not in chosen]
        if candidates:
            chosen[i] = candidates[0]
    return chosen


@dataclasses.dataclass
class _Search:
    """What :func:`discover` computes once and the plugins reuse."""

    fit: FitResult
    probes: ProbeSet
    table: MeasurementTable  # the rows searched
    residual: Residual
    searched: Searched
    means: dict[str, float]
    weight: np.ndarray  # 1/σ of the rows searched


def discover(fit: FitResult, probes: ProbeSet, seed: int = 0, plugins: bool = True) -> Discovery:
    """The channel terms that ``fit``'s residual follows beyond what its model absorbs
    (module docstrings of :mod:`mows.lab.diagnosis.discovery`), each with its plugin
    (``plugins=False``: without, on :data:`SCREEN_RESAMPLES` half-samples, for a search that
    only needs the terms' stand-ins); ``seed`` draws the half-samples (and, for a table longer
    than :data:`MAX_ROWS`, the stratified rows searched)."""
    table = fit.table if fit.problem.rows is None else fit.table.subset(fit.problem.rows)
    if fit.invalid_rows.size or len(table) < MIN_ROWS:  # residuals of rows without a frequency are no data
        why = "the model has no frequency at some rows" if fit.invalid_rows.size else f"{len(table)} rows are too few"
        return Discovery([], 0, 0, DEGREE, f"No search beyond the catalog: {why}.", fit.model.name)
    kept = stratified_rows(table.sweep_ids, MAX_ROWS, seed)
    table = table.subset(kept) if len(kept) < len(table) else table
    weight = fit.problem.row_weight[kept]
    jacobian = unit_columns(fit.jacobian[kept])
    model_basis = orthonormal_basis(jacobian)
    factors = factor_values(table, probes)
    # The screen (stand-ins beside which catalog effects are judged, once per candidate of every
    # step) searches the frequency alone: the channels' Jacobians cost a model evaluation each.
    channels = CHANNELS if plugins else (FREQUENCY,)
    searched = searchable(library_terms(factors, jacobians(fit, table, weight, channels), weight), model_basis)
    residual = Residual(fit.weighted_residual[kept], jacobian, model_basis.shape[1], cv_folds(table))
    means = factor_centres({name: table.columns[name] for name in factors if factor(name).centred}, probes)
    search = _Search(fit, probes, table, residual, searched, means, weight)
    groups = fit.problem.inverse[kept]
    units = groups if len(np.unique(groups)) >= MIN_UNITS else np.arange(len(table))
    resamples = RESAMPLES if plugins else SCREEN_RESAMPLES
    rng = np.random.default_rng(seed)
    frequencies = selection_frequencies(searched, residual.values, jacobian, units, rng, resamples)
    passed = significant(searched, [int(j) for j in np.flatnonzero(frequencies >= STABLE_FRACTION)], residual)
    if passed.chosen and (simpler := simplest(searched, passed)) != passed.chosen:
        passed = significant(searched, simpler, residual)
    found = sorted(
        (_term(search, passed, i, frequencies, plugins) for i in range(len(passed.chosen))),
        key=lambda t: -t[0].cv_gain_chi2,
    )
    terms = [term for term, _ in found]
    text = summary(terms, len(searched.terms), resamples, STABLE_FRACTION) + (
        f" (Searched on {len(table)} stratified rows of {fit.n}.)" if len(table) < fit.n else ""
    )
    return Discovery(terms, len(searched.terms), resamples, DEGREE, text, fit.model.name, tuple(e for _, e in found))


def _term(
    search: _Search, passed: Refit, i: int, frequencies: np.ndarray, plugins: bool
) -> tuple[DiscoveredTerm, Effect]:
    """Term ``i`` of ``passed`` as found, and its plugin's effect (the stand-in)."""
    j = passed.chosen[i]
    term, length = search.searched.terms[j], search.searched.length[j]
    strength = float(passed.coefficients[i] / length)
    std = float(math.sqrt(passed.covariance[i, i]) / length)
    reading = readings.reading(term.channel, term.factors)
    plugin = Plugin(term.channel, term.factors, search.means, bound_for(strength, std), search.probes, reading)
    parameter, why = None, ""
    if term.channel is FREQUENCY:
        why = "no channel of the potential makes this term on these rows"
        plugin = dataclasses.replace(plugin, note=f" (Last resort: {why}.)")
    elif not writable(term.channel):
        why = f"the plugin interface has no {term.channel.output} output"
        plugin = _last_resort(search, j, reading, why)
    if plugins:
        plugin, parameter, why = _fitted_plugin(search, passed, i, plugin, why)
    found = DiscoveredTerm(
        term.name,
        term.channel.name,
        term.factors,
        readings.family(term.channel, term.factors),
        strength,
        std,
        float(frequencies[j]),
        float(passed.cv_gain_chi2[i]),
        reading,
        plugin.source(),
        term.unit,
        term.channel.unit,
        float(passed.p_values[i]),
        tuple(search.searched.aliases[j]),
        tuple(readings.alternatives(search.searched, j, float(passed.gain_chi2[i]))) if plugins else (),
        parameter,
        plugin.channel.output,
        plugin.line(),
        plugin.name,
        why,
        _term_fit(search, passed, i),
    )
    return found, load_source(plugin.source(), plugin.name)


def _last_resort(search: _Search, j: int, reading: str, why: str) -> Plugin:
    """The additive frequency term whose column is closest to term ``j``'s, written as a plugin."""
    searched = search.searched
    frequency = [k for k, term in enumerate(searched.every) if term.channel is FREQUENCY]
    closest = max(frequency, key=lambda k: abs(float(searched.every_unit[:, k] @ searched.unit[:, j])))
    factors = searched.every[closest].factors
    return Plugin(FREQUENCY, factors, search.means, 1.0, search.probes, reading, f" (Last resort: {why}.)")


def _term_fit(search: _Search, passed: Refit, i: int) -> TermFit:
    """Term ``i`` of ``passed`` beside the residual it explains (:class:`TermFit`)."""
    j, others = passed.chosen[i], [k for k in range(len(passed.chosen)) if k != i]
    columns = search.searched.unit[:, [passed.chosen[k] for k in others]]
    explained = search.residual.values - columns @ passed.coefficients[others]
    beyond = search.searched.unit[:, j] * search.searched.length[j]
    return TermFit(beyond / search.weight, explained / search.weight, 1.0 / search.weight)


def _fitted_plugin(
    search: _Search, passed: Refit, i: int, plugin: Plugin, why: str
) -> tuple[Plugin, FittedParameter, str]:
    """The plugin and its parameter fitted on this table through its own signature; where that
    signature does not reproduce the term, the closest additive frequency term (module docstring)."""
    j = passed.chosen[i]
    column = _signature(search, plugin)
    cosine = abs(float(column @ search.searched.unit[:, j])) / max(float(np.linalg.norm(column)), 1e-300)
    if plugin.channel is not FREQUENCY and cosine < PHYSICAL_COSINE:
        why = f"its plugin in the {plugin.channel.name} channel does not reproduce it on these rows (cos {cosine:.2f})"
        plugin = _last_resort(search, j, plugin.reading, why)
        column = _signature(search, plugin)
    parameter = _fitted(search, passed, i, column, plugin)
    bound = bound_for(parameter.value, parameter.std)
    if bound != plugin.bound:  # the first guess was off: the derivative again, within the final bounds
        plugin = dataclasses.replace(plugin, bound=bound)
        parameter = _fitted(search, passed, i, _signature(search, plugin), plugin)
    return plugin, parameter, why


def _signature(search: _Search, plugin: Plugin) -> np.ndarray:
    """The plugin's signature d(weighted residual)/d(parameter) beside the model at 0, projected."""
    effect = load_source(plugin.source(), plugin.name)
    column = search.fit.extension_columns(effect, search.table)[:, 0]
    return project_out(column[:, None], orthonormal_basis(search.residual.jacobian))[:, 0]


def _fitted(search: _Search, passed: Refit, i: int, column: np.ndarray, plugin: Plugin) -> FittedParameter:
    """The plugin's parameter by least squares of the residual on its signature beside the other
    terms, σ inflated by the scatter they leave."""
    design = np.column_stack([column, np.delete(search.searched.unit[:, passed.chosen], i, axis=1)])
    coefficients = np.linalg.lstsq(design, search.residual.values, rcond=None)[0]
    variance = np.linalg.pinv(design.T @ design)[0, 0] * search.residual.scatter(design)
    # The signature is d(weighted residual)/dp = −w·df/dp: the parameter is minus the coefficient.
    return FittedParameter(plugin.channel.parameter, -float(coefficients[0]), math.sqrt(variance), plugin.unit)
