"""One call from a table to a verdict: fit, diagnose, select effects, check physics (the live API).

:func:`analyse` is what the mapper node calls after every sweep; :class:`LabReport` maps onto
``mows_msgs/ModelReport`` (model, effects, n, chi2_dof, bic, cv_rms_hz, verdict, structure,
candidates) and each :class:`mows.lab.diagnosis.candidates.Candidate` onto ``CandidateEffect``.

The steps, in the lab's pipeline order: the table (:mod:`mows.lab.data.readers`), the base model
and the named effects (:mod:`mows.lab.model.catalog`, :mod:`mows.lab.model.frequency_model`), the fit, its
diagnosis (:mod:`mows.lab.diagnosis.verdict`), with ``auto`` the stepwise selection
(:mod:`mows.lab.selection.stepwise`), then the physics checks below.


Every effect of the final model with a physical value gets a consistency check: its free fit
with the rest of the model (value ± σ; for one held at physics, a refit with it set free); a
physical value more than 3σ from it is reported in the notes.

A final model that leaves structure no catalog effect explains, or that needs a generic
correction, hides physics: the report carries the search beyond the catalog
(:func:`mows.lab.diagnosis.discovery.discover`) as ``discovery``. For ``needs_generic_term`` it
searches the residual of the final model without its generic corrections, which would
otherwise absorb what they stand for.
"""

from __future__ import annotations

import dataclasses
import os
import pathlib
import tempfile
from collections.abc import Callable, Iterable, Sequence

import numpy as np

from mows.lab.data.probe_rows import ProbeSet, probe_parts, with_probes
from mows.lab.data.readers import from_sweep, load_table
from mows.lab.data.reference import Reference
from mows.lab.data.table import MeasurementTable, TableError
from mows.lab.diagnosis import plausibility
from mows.lab.diagnosis.candidates import Candidate, physics_deviation
from mows.lab.diagnosis.discovery import DiscoveredTerm, Discovery, discover
from mows.lab.diagnosis.indistinguishable import Group
from mows.lab.diagnosis.verdict import Diagnosis, Verdict, diagnose
from mows.lab.model.catalog import catalog, resolve
from mows.lab.model.effects import AT_PHYSICS
from mows.lab.model.factors import unevaluable_rows
from mows.lab.model.frequency_model import FitResult, FrequencyModel
from mows.lab.model.least_squares import FittedParameter, parameters_dict
from mows.lab.selection.stepwise import MAX_AUTO_STEPS, HistoryStep, history_step, search
from mows.physics.probe import Probe
from mows.records.json_numbers import finite_or_none
from mows.sweep.events import SweepMap

CHECK_SIGMAS = 3.0  # a physical value further than this from its free fit is noted
INCONSISTENT_SIGMAS = 5.0  # … and further than this makes a statistically adequate model inconsistent
DISCOVERY_ROUNDS = 3  # terms beyond the catalog added one after another (analyse_discovering)


@dataclasses.dataclass
class PhysicsCheck:
    """An effect of the final model that has a physical value, against its free fit with the
    rest (for an effect held at physics, a refit with it set free)."""

    effect: str
    held: bool  # held at physics in the final model
    parameters: list[FittedParameter]  # of the free fit
    deviation_sigma: float  # largest |value − physical|/σ

    def to_dict(self) -> dict:
        return {
            "effect": self.effect,
            "held_at_physics": self.held,
            "parameters": parameters_dict(self.parameters),
            "deviation_sigma": finite_or_none(self.deviation_sigma),
        }


@dataclasses.dataclass
class LabReport:
    """The lab's answer for one table: the diagnosis of the final model, with how it was reached
    (``history`` from ``base``) and its physics checks. The properties map onto
    mows_msgs/ModelReport."""

    diagnosis: Diagnosis  # of the final model: its fit, candidates, groups and verdict
    base: FitResult
    history: list[HistoryStep]
    notes: list[str]
    physics_checks: list[PhysicsCheck] = dataclasses.field(default_factory=list)

    @property
    def fit(self) -> FitResult:
        """The final model's fit."""
        return self.diagnosis.fit

    @property
    def model(self) -> str:
        return self.fit.model.name

    @property
    def effects(self) -> list[str]:
        """The final model's effects as labels: ``name (at physics)`` for one held at its physical value."""
        return self.fit.model.labels

    @property
    def n(self) -> int:
        return self.fit.n

    @property
    def chi2_dof(self) -> float:
        return self.fit.chi2_dof

    @property
    def bic(self) -> float:
        return self.fit.bic

    @property
    def cv_rms_hz(self) -> float:
        """The final step's cross-validated rms prediction error (NaN where not computed)."""
        return self.history[-1].cv_rms_hz

    @property
    def verdict(self) -> Verdict:
        return self.diagnosis.verdict

    @property
    def structure(self) -> str:
        """The residual structure in words."""
        return self.diagnosis.structure.summary

    @property
    def candidates(self) -> list[Candidate]:
        return self.diagnosis.candidates

    @property
    def groups(self) -> list[Group]:
        return self.diagnosis.groups

    @property
    def untestable(self) -> dict[str, str]:
        """Effect name → why it cannot be tested."""
        return self.diagnosis.untestable

    @property
    def discovery(self) -> Discovery | None:
        """The search beyond the catalog (module docstring); None when the verdict asks for none."""
        return self.diagnosis.discovery

    @property
    def effect_names(self) -> list[str]:
        """The final model's effects by name, whatever their form."""
        return self.fit.model.effect_names

    def effect_parameter(self, name: str) -> tuple[float, float]:
        """(value, σ) of ``effect.parameter`` in the final fit, or, for an effect held at
        physics, in its free fit (the consistency check)."""
        fitted = {p.name: (p.value, p.std) for p in self.fit.parameters()}
        fitted.update({f"{c.effect}.{p.name}": (p.value, p.std) for c in self.physics_checks for p in c.parameters})
        if name not in fitted:
            raise KeyError(f"no parameter {name} in the final model {self.model}")
        return fitted[name]

    def to_dict(self) -> dict:
        """The JSON form (docs/model_lab.md): base, candidates, groups, history, verdict, structure…"""
        return {
            "base": {"chi2_dof": self.base.chi2_dof, "n": self.base.n, "bic": self.base.bic},
            "model": self.model,
            "effects": self.effects,
            "final": {
                "chi2_dof": self.chi2_dof,
                "bic": self.bic,
                "cv_rms_hz": finite_or_none(self.cv_rms_hz),
                "parameters": parameters_dict(self.fit.parameters()),
                "not_identifiable": [
                    name for name, known in zip(self.fit.model.parameter_names, self.fit.identifiable) if not known
                ],
            },
            "physics_checks": [c.to_dict() for c in self.physics_checks],
            "candidates": [c.to_dict() for c in self.candidates],
            "groups": [g.to_dict() for g in self.groups],
            "history": [h.to_dict() for h in self.history],
            "verdict": self.verdict,
            "verdict_explanation": self.diagnosis.explanation,
            "structure": self.diagnosis.structure.to_dict(),
            "discovery": None if self.discovery is None else self.discovery.to_dict(),
            "untestable": self.untestable,
            "notes": self.notes,
        }


def analyse(
    table: MeasurementTable | str | os.PathLike[str],
    probes: ProbeSet,
    effects: Iterable[str] | None = None,
    auto: bool = False,
    plugins: Iterable[str | pathlib.Path] = (),
    rank: bool = True,
    cross_validate: bool = True,
) -> LabReport:
    """Fit the published model plus ``effects`` (names) to ``table`` and diagnose what is missing.

    Parameters
    ----------
    table : a :class:`MeasurementTable`, a CSV path or a bag (see :func:`load_table`).
    probes : :class:`mows.lab.data.probe_rows.ProbeSet`: the probes of the table's rows
        (:meth:`~mows.lab.data.probe_rows.ProbeSet.for_table`), or a set of one
        (:meth:`~mows.lab.data.probe_rows.ProbeSet.one`), lent to every probe a ``probe`` column names.
    effects : effect names added one by one to the base model (each a step of the history);
        ``name (at physics)`` adds the effect held at its physical value.
    auto : then select effects stepwise (module docstring).
    plugins : plugin files or entry-point names whose effects join the catalog.
    rank : test the catalog's candidates (``False``: fit and residual structure only).
    cross_validate : compute the cross-validated error (whole sweeps held out) of every step.
    """
    table, probes = with_probes(load_table(table), probes)
    table = _evaluable(table, probes)
    available = catalog(plugins)
    fit = FrequencyModel(probes).fit(table)
    base = fit
    history = [history_step(fit, cross_validate)]
    for effect in resolve(list(effects or ()), available):
        fit = (fit.model + effect).fit(table, start=np.concatenate([fit.effect_values, effect.off_values]))
        history.append(history_step(fit, cross_validate, f"add {effect.label}"))
    pool = list(available.values()) if rank else []
    steps = MAX_AUTO_STEPS if auto else 0
    found = search(diagnose(fit, pool, probes, for_report=False), pool, probes, history, cross_validate, steps)
    fit = found.fit
    if not rank:
        found.explanation += " (Candidate effects were not tested: run `mows lab diagnose`.)"
    checks = physics_checks(fit)
    if found.verdict == Verdict.ADEQUATE:
        found.verdict, found.explanation = _physics_verdict(fit, probes, checks, found.explanation)
    if found.verdict == Verdict.NEEDS_GENERIC_TERM:
        found.discovery = discover(without_generic(fit), probes)
    notes = list(table.notes) + [_check_note(c) for c in checks if c.deviation_sigma > CHECK_SIGMAS]
    return LabReport(found, base, history, notes, checks)


def _evaluable(table: MeasurementTable, probes: ProbeSet) -> MeasurementTable:
    """The table without the rows the potential cannot evaluate, each named with the reason in
    the notes (:func:`mows.lab.model.factors.unevaluable_rows`); TableError when no row is left."""
    distinct, inverse = FrequencyModel(probes).groups(table)
    found = {}  # a reason holds for every row of its configuration
    for rows, part, entry in probe_parts(distinct, probes):
        found.update({int(rows[row]): reason for row, reason in unevaluable_rows(part, entry.probe).items()})
    problems = {int(row): found[int(inverse[row])] for row in np.flatnonzero(np.isin(inverse, list(found)))}
    if len(problems) == len(table):
        raise TableError(f"the model cannot evaluate any row of {table.source}: {next(iter(problems.values()))[0]}")
    return table.without_rows(problems) if problems else table


def physics_checks(fit: FitResult) -> list[PhysicsCheck]:
    """For every effect of ``fit`` with a physical value: its free fit with the rest of the
    model (a refit for one held at physics), and how far the physical value lies from it."""
    checks = []
    for effect in fit.model.effects:
        if effect.physical is None:
            continue
        free = fit
        if effect.free is not None:  # held at physics (Effect.fixed)
            freed = fit.model.without(effect) + effect.free
            free = freed.fit(fit.table, start=np.concatenate([fit.values_without(effect), effect.physical]))
        parameters = free.effect_parameters(effect.name)
        checks.append(PhysicsCheck(effect.name, effect.fixed, parameters, physics_deviation(effect, parameters)))
    return checks


def without_generic(fit: FitResult) -> FitResult:
    """``fit``'s model without its generic corrections, refitted from the other effects' values:
    the residual in which discovery looks for what the corrections stand for."""
    sizes = [len(e.parameters) for e in fit.model.effects]
    parts = np.split(fit.effect_values, np.cumsum(sizes)[:-1]) if sizes else []
    kept = [(e, values) for e, values in zip(fit.model.effects, parts) if not e.generic]
    start = np.concatenate([values for _, values in kept]) if kept else np.zeros(0)
    return FrequencyModel(fit.model.probe, [e for e, _ in kept]).fit(fit.table, start=start)


def _physics_verdict(
    fit: FitResult, probes: ProbeSet, checks: Sequence[PhysicsCheck], explanation: str
) -> tuple[Verdict, str]:
    """(verdict, explanation) of a model whose residuals the statistics call adequate:
    ``inconsistent_physics`` when an effect's free fit lies more than 5σ from its physical
    value, or a parameter where physics does not allow it (:func:`plausibility.conflicts`: an
    effect the user added that is adequate only at an impossible value), else
    ``needs_generic_term`` when a generic correction is in the model (what it stands for must
    still be found), else ``adequate``."""
    inconsistent = [c for c in checks if c.deviation_sigma > INCONSISTENT_SIGMAS]
    impossible = plausibility.conflicts(fit, probes)
    generic = [e for e in fit.model.effects if e.generic]
    if not inconsistent and not impossible and not generic:
        return Verdict.ADEQUATE, explanation
    found = [
        f"{c.effect} ({'held at physics; its free fit gives' if c.held else 'free:'} {_values(c.parameters)}) "
        f"is {c.deviation_sigma:.1f}σ from its physical value"
        for c in inconsistent
    ]
    found += [conflict.text for conflict in impossible]
    found += [
        f"{e.name} ({_values(fit.effect_parameters(e.name))}) is a generic correction with no physical value "
        f"of its own; to find what it stands for: {e.check}"
        for e in generic
    ]
    verdict = Verdict.INCONSISTENT_PHYSICS if inconsistent or impossible else Verdict.NEEDS_GENERIC_TERM
    return verdict, (
        "The residuals are consistent with noise, but the physics is not: "
        + "; ".join(found)
        + ". "
        + explanation.removeprefix("The model explains the data: ")
    )


def _values(parameters: Iterable[FittedParameter]) -> str:
    return ", ".join(p.text() for p in parameters)


def _check_note(check: PhysicsCheck) -> str:
    values = ", ".join(f"{p.name} = {p.value:.4g} ± {p.std:.2g}" for p in check.parameters)
    state = "is held at its physical value, but its free fit gives" if check.held else "is fitted free at"
    return (
        f"{check.effect} {state} {values}, {check.deviation_sigma:.1f}σ from its physical value: the "
        "physics as predicted misses something here, or the parameter absorbs another effect"
    )


def analyse_discovering(
    table: MeasurementTable,
    probes: ProbeSet,
    save: Callable[[DiscoveredTerm], pathlib.Path],
    effects: Iterable[str] = (),
    plugins: Iterable[str | pathlib.Path] = (),
    cross_validate: bool = True,
    rounds: int = DISCOVERY_ROUNDS,
) -> tuple[LabReport, list[DiscoveredTerm]]:
    """:func:`analyse` with ``auto``, then, while the search beyond the catalog finds a term: the
    strongest term's plugin added after the effects the model already holds, and the table
    analysed again, so that the report's history shows the error falling through it; the plugin
    kept is saved by ``save`` (which returns its path). Stops after ``rounds`` terms, at a term
    already added, or when a term added does not lower χ²/dof (its report is then not kept).
    Returns the last report and the terms added, in order.

    A term that leaves a free catalog effect more than :data:`INCONSISTENT_SIGMAS` from its
    physical value was read beside a parameter that absorbs part of it (a free static deflection
    takes an induced moment's harmonic 2, and a field along the lever fits what is left): the
    search runs again with that effect held at physics, and its term replaces the first when its
    model is consistent with physics and lowers χ²/dof."""
    plugins, added = list(plugins), list[DiscoveredTerm]()
    report = analyse(table, probes, effects, auto=True, plugins=plugins, cross_validate=cross_validate)
    with tempfile.TemporaryDirectory() as scratch:
        trying = _Trying(table, probes, pathlib.Path(scratch), cross_validate)
        for _ in range(rounds):
            found = report.discovery
            if found is None or not found.terms or found.terms[0].effect_name in {t.effect_name for t in added}:
                break
            term, trial = found.terms[0], trying.added(report.effects, found.terms[0], plugins)
            if held := _pushed_from_physics(trial):
                term, trial = trying.beside_physics(report, held, plugins, (term, trial))
            if not trial.chi2_dof < report.chi2_dof:
                break
            report, plugins = trial, [*plugins, save(term)]
            added.append(term)
    return report, added


def _pushed_from_physics(report: LabReport) -> list[str]:
    """The free effects of ``report`` whose free fit lies beyond :data:`INCONSISTENT_SIGMAS`."""
    return [c.effect for c in report.physics_checks if not c.held and c.deviation_sigma > INCONSISTENT_SIGMAS]


@dataclasses.dataclass
class _Trying:
    """Trials of :func:`analyse_discovering`: a term's plugin written to ``scratch`` and added."""

    table: MeasurementTable
    probes: ProbeSet
    scratch: pathlib.Path
    cross_validate: bool

    def added(self, labels: Sequence[str], term: DiscoveredTerm, plugins: Sequence[str | pathlib.Path]) -> LabReport:
        path = self.scratch / f"{term.effect_name}.py"
        path.write_text(term.plugin, encoding="utf-8")
        chosen = [*labels, term.effect_name]
        return analyse(
            self.table, self.probes, chosen, auto=True, plugins=[*plugins, path], cross_validate=self.cross_validate
        )

    def beside_physics(
        self,
        report: LabReport,
        held: Sequence[str],
        plugins: Sequence[str | pathlib.Path],
        first: tuple[DiscoveredTerm, LabReport],
    ) -> tuple[DiscoveredTerm, LabReport]:
        """``first`` (term, trial), or the term found beside ``report``'s effects with ``held``
        at physics and its trial, when that trial is consistent with physics and lowers χ²/dof."""
        labels = [f"{label}{AT_PHYSICS}" if label in held else label for label in report.effects]
        again = analyse(self.table, self.probes, labels, plugins=plugins, rank=False, cross_validate=False).discovery
        if again is None or not again.terms or again.terms[0].effect_name == first[0].effect_name:
            return first
        trial = self.added(labels, again.terms[0], plugins)
        if _pushed_from_physics(trial) or not trial.chi2_dof < report.chi2_dof:
            return first
        return again.terms[0], trial


def analyse_sweep(sweep: SweepMap, reference: Reference, probe: Probe, auto: bool = False) -> LabReport:
    """The model lab on one finished sweep (the mapper's, live): its table in the static
    ``reference`` with each ring-down's start swing from the sweep's decomposition
    (:func:`mows.lab.data.readers.from_sweep`), analysed as :func:`analyse` does, with ``auto``.
    ValueError (a :class:`TableError`) for a sweep whose table the lab cannot use."""
    return analyse(from_sweep(sweep.record, reference, probe, sweep.decomposition), ProbeSet.one(probe), auto=auto)
