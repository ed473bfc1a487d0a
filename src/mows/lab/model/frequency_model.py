"""The frequency model: the published model (Eq. 6) plus effects, its fit and cross-validation.

The weighted residuals, their Jacobian and the fitted result (uncertainties, BIC,
cross-validation) are :mod:`mows.lab.model.least_squares`.

``FrequencyModel(probes) + catalog()["gravity"] + …`` composes like astropy.modeling; each
effect brings parameters with units and physical bounds like lmfit. The prediction for row i is

    f_i = f00·h_i(p) + c_i(p),

with h from the potential (:func:`mows.lab.model.factors.frequency_factor`), p the effect parameters
and c the additive frequency contributions of plugins. The base model has no effect: h is
Eq. 6, √(1 + (m·Bx' + l·m·Gx'x')/kM), with the table's reference field and gradient.

Nuisance parameter: f00 is always fitted (the zero-field frequency drifts with wear, and the
calibration is never perfect), one per probe for a table of several probes
(:class:`mows.lab.data.probe_rows.ProbeSet`, whose rows are each evaluated with their own probe's
constants). Nothing else in the base model is free.

Fit: weighted least squares (σ = ``f_std_hz``) by scipy's trust-region reflective method within
the parameters' bounds, f00 started from its closed-form optimum. The Jacobian column of f00
is exact (h); the others are forward differences with steps of 1 % of each parameter's
typical size (the effects are smooth and nearly linear there). χ² = Σ((f − model)/σ)²,
BIC = χ² + k·ln n (the Gaussian likelihood with known σ, k free parameters including f00).
Uncertainties come from (JᵀJ)⁻¹ and are inflated by √(χ²/dof) when that exceeds 1 (Birge ratio:
an incomplete model should not claim the precision of a complete one).
"""

from __future__ import annotations

import dataclasses
import functools
import weakref
from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import scipy.optimize

from mows.lab.data.probe_rows import ProbeSet, probe_parts
from mows.lab.data.table import MeasurementTable
from mows.lab.model.configuration import Configuration, default_window_s, distinct_rows_of
from mows.lab.model.effects import Effect, Parameter, untestable_reason
from mows.lab.model.factors import base_start_swing_rad, frequency_factor, ringdown_nodes
from mows.lab.model.least_squares import FitResult, Problem
from mows.physics.probe import Probe


class FrequencyModel:
    """The published frequency model plus ``effects`` for a table's ``probes``
    (:class:`~mows.lab.data.probe_rows.ProbeSet`; one probe is a set of one).

    ``model + effect`` and ``effect + model`` give new models; parameters are named by the set's
    f00s (``f00_hz``, or ``probe_<id>.f00_hz``) and ``<effect>.<parameter>``.
    ``FrequencyModel() + a + b`` is a sum of effects alone, without probes: not a model of any
    table (it cannot be evaluated), only a part to add to a model that has them.
    """

    def __init__(self, probes: ProbeSet | None = None, effects: Sequence[Effect] = ()) -> None:
        self.probe = probes  # the table's probe set
        names = [e.name for e in effects]
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise ValueError(f"effect {', '.join(repeated)} appears more than once in the model")
        self.effects = tuple(effects)

    @classmethod
    def combine(cls, left: FrequencyModel | Effect, right: FrequencyModel | Effect) -> FrequencyModel:
        parts = [left, right]
        probes = next((p.probe for p in parts if isinstance(p, FrequencyModel) and p.probe is not None), None)
        found: list[Effect] = []
        for part in parts:
            if isinstance(part, FrequencyModel):
                found.extend(part.effects)
            elif isinstance(part, Effect):
                found.append(part)
            else:
                raise TypeError(f"cannot add {type(part).__name__} to a frequency model")
        return cls(probes, found)

    def __add__(self, other: FrequencyModel | Effect) -> FrequencyModel:
        return FrequencyModel.combine(self, other)

    def __radd__(self, other: FrequencyModel | Effect) -> FrequencyModel:
        return FrequencyModel.combine(other, self)

    # --- description ----------------------------------------------------------------------
    @property
    def name(self) -> str:
        return " + ".join(["eq6"] + self.labels)

    @property
    def effect_names(self) -> list[str]:
        return [e.name for e in self.effects]

    @property
    def labels(self) -> list[str]:
        """The effects' names with their form (``… (at physics)`` when held at physics)."""
        return [e.label for e in self.effects]

    def without(self, effect: Effect) -> FrequencyModel:
        return FrequencyModel(self.probe, [e for e in self.effects if e is not effect])

    @property
    def parameters(self) -> list[tuple[str, Parameter]]:
        """(qualified name, Parameter) for the effect parameters, in fit order."""
        return [(f"{e.name}.{p.name}", p) for e in self.effects for p in e.parameters]

    @property
    def off_values(self) -> np.ndarray:
        """The effect parameter values (fit order) at which every effect is absent."""
        return np.concatenate([np.zeros(0)] + [e.off_values for e in self.effects])

    @property
    def f00_names(self) -> list[str]:
        """The nuisance parameters: one f00 per probe (:attr:`ProbeSet.f00_names`)."""
        return self._require_probes().f00_names

    @property
    def f00_count(self) -> int:
        return len(self.f00_names)

    @property
    def parameter_names(self) -> list[str]:
        return self.f00_names + [name for name, _ in self.parameters]

    def probe_index(self, table: MeasurementTable) -> np.ndarray:
        """Each row's f00 (its position in :attr:`f00_names`), (n,)."""
        return self._require_probes().index(table)

    def __repr__(self) -> str:
        return f"FrequencyModel({self.name})"

    # --- evaluation -------------------------------------------------------------------------
    def _require_probes(self) -> ProbeSet:
        if self.probe is None:
            raise ValueError("this model has no probes: build it as FrequencyModel(probes) + effects")
        return self.probe

    def groups(self, table: MeasurementTable) -> tuple[MeasurementTable, np.ndarray]:
        """(distinct, inverse): one row of each configuration group of ``table`` for this model,
        and each row's group (:func:`distinct_table` over :meth:`read_columns`)."""
        return distinct_table(table, self.read_columns(table))

    def read_columns(self, table: MeasurementTable) -> frozenset[str]:
        """The columns of ``table`` this model's frequency depends on: those that building its
        configuration reads (:meth:`Configuration.base` and every effect's ``apply``, recorded on
        the table's first row), but the measured ones (``MEASURED``)."""
        row = table.subset(np.arange(1))
        recorder = _RecordingColumns(row.columns)
        object.__setattr__(row, "columns", recorder)
        # Reading the row's probe (each probe's rows are evaluated with its own constants) records
        # its column where the set is named by it.
        ((_, part, entry),) = probe_parts(row, self._require_probes())
        self._configuration(part, self.off_values, entry.probe)
        return frozenset(name for name in recorder.read if table.has(name) and name not in MEASURED)

    def group_factors(
        self, distinct: MeasurementTable, values: Sequence[float] | np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(h, c) of f = f00·h + c of each row of a :meth:`groups` table at effect parameter
        values ``values`` (fit order)."""
        h, c = np.empty(len(distinct)), np.empty(len(distinct))
        for rows, part, entry in probe_parts(distinct, self._require_probes()):
            config = self._configuration(part, values, entry.probe)
            nodes = functools.partial(cached_nodes, distinct)
            h[rows], c[rows] = frequency_factor(config, entry.probe, nodes)
        return h, c

    def _configuration(
        self, table: MeasurementTable, values: Sequence[float] | np.ndarray, probe: Probe
    ) -> Configuration:
        config = Configuration.base(table, probe)
        bounds = np.cumsum([0] + [len(e.parameters) for e in self.effects])
        ordered = sorted(range(len(self.effects)), key=lambda i: self.effects[i].stage)
        for i in ordered:
            self.effects[i].apply(config, table, probe, *(float(v) for v in values[bounds[i] : bounds[i + 1]]))
        return config

    def factors(self, table: MeasurementTable, values: Sequence[float] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(h, c) of f = f00·h + c of every row at effect parameter values ``values`` (fit order)."""
        distinct, inverse = self.groups(table)
        h, c = self.group_factors(distinct, values)
        return h[inverse], c[inverse]

    def predict(self, table: MeasurementTable, values: FitResult | Sequence[float] | np.ndarray) -> np.ndarray:
        """f (Hz) for ``values`` = [f00 (one per probe), effect parameters…] (or a :class:`FitResult`)."""
        x = values.values if isinstance(values, FitResult) else np.asarray(values, float)
        h, c = self.factors(table, x[self.f00_count :])
        return x[: self.f00_count][self.probe_index(table)] * h + c

    # --- fit ------------------------------------------------------------------------------
    def fit(
        self,
        table: MeasurementTable,
        start: Sequence[float] | np.ndarray | None = None,
        rows: np.ndarray | None = None,
    ) -> FitResult:
        """Weighted least-squares fit to ``table`` (to its ``rows``, indices, when given: a
        cross-validation fold); ``start`` = effect parameter values (default: every effect off)."""
        probes = self._require_probes()
        for effect in self.effects:
            reason = untestable_reason(effect, table, probes)
            if reason:
                raise ValueError(f"effect {effect.name} cannot be fitted to this table: {reason}")
        problem = Problem(self, table, rows)
        p0 = self.off_values if start is None else np.asarray(start, float)
        x0 = np.concatenate([problem.best_f00(p0), p0])
        if x0.size == self.f00_count:  # f00 alone enters linearly: the closed form is the optimum
            return problem.result(x0, True, "f00 in closed form")
        lower = np.array([0.0] * self.f00_count + [p.lower for _, p in self.parameters])
        upper = np.array([np.inf] * self.f00_count + [p.upper for _, p in self.parameters])
        x0 = np.clip(x0, lower, upper)
        solution = scipy.optimize.least_squares(
            problem.residual,
            x0,
            jac=problem.jacobian,
            bounds=(lower, upper),
            x_scale="jac",
            method="trf",
            xtol=1e-10,
            ftol=1e-12,
            gtol=1e-12,
            max_nfev=60,
        )
        return problem.result(solution.x, solution.success, _in_words(solution))


def _in_words(solution: scipy.optimize.OptimizeResult) -> str:
    """How the fit ended, in the lab's words (scipy's name its own internals)."""
    if solution.success:
        return f"converged in {solution.nfev} model evaluations"
    return f"stopped at the limit of {solution.nfev} model evaluations before the tolerances were met"


def table_start_swing_rad(table: MeasurementTable, probes: ProbeSet) -> np.ndarray:
    """Each row's start swing at the table's reference field and its probe's stop
    (:func:`mows.lab.model.factors.base_start_swing_rad`), evaluated once per
    configuration group of the published model."""
    distinct, inverse = FrequencyModel(probes).groups(table)
    found = np.empty(len(distinct))
    for rows, part, entry in probe_parts(distinct, probes):
        found[rows] = base_start_swing_rad(part, entry.probe)
    return found[inverse]


# --- the table's configuration groups, and ring-down amplitude nodes, cached per table ------
# Columns that are measurements of a row, not inputs of its model.
MEASURED = ("f_hz", "f_std_hz", "sweep")
# table → {key columns: (one row of each group as a table, each row's index into it)}
_DISTINCT: weakref.WeakKeyDictionary[MeasurementTable, dict[frozenset[str], tuple[MeasurementTable, np.ndarray]]] = (
    weakref.WeakKeyDictionary()
)


def distinct_table(table: MeasurementTable, names: frozenset[str]) -> tuple[MeasurementTable, np.ndarray]:
    """(distinct, inverse): a table of one row per group of ``table`` and, for each row, its
    row in ``distinct``. Rows are in one group when the columns ``names`` are bitwise equal:
    effects compute a row's configuration from that row's columns (docs/model_lab.md), so rows
    equal in every column a model reads have the same model frequency for any parameters. The
    other columns of ``distinct`` hold the first row's values. The ring-down window comes from
    the whole table (``default_window_s``)."""
    cached = _DISTINCT.setdefault(table, {})
    if names not in cached:
        first, inverse = distinct_rows_of([table.columns[name] for name in sorted(names)] or [np.zeros(len(table))])
        if len(first) == len(table):
            # Every row its own group (a column such as time that an effect reads): the table's
            # own columns serve, not a copy of them.
            first = inverse = np.arange(len(table))
            columns = dict(table.columns)
        else:
            columns = {name: values[first] for name, values in table.columns.items()}
        columns["duration_s"] = table.columns.get("duration_s", default_window_s(table))[first]
        cached[names] = (dataclasses.replace(table, columns=columns), inverse)
    return cached[names]


class _RecordingColumns(dict):
    """A table's columns that note which of them are read (:meth:`FrequencyModel.read_columns`);
    reading them all at once (iterating) notes all."""

    def __init__(self, columns: Mapping[str, np.ndarray]) -> None:
        super().__init__(columns)
        self.read: set[str] = set()

    def __getitem__(self, name: str) -> np.ndarray:
        self.read.add(name)
        return super().__getitem__(name)

    def get(self, name: str, default: Any = None) -> Any:
        self.read.add(name)
        return super().get(name, default)

    def __iter__(self) -> Iterator[str]:
        self.read.update(self.keys())
        return super().__iter__()

    def items(self) -> Any:
        self.read.update(self.keys())
        return super().items()

    def values(self) -> Any:
        self.read.update(self.keys())
        return super().values()


# --- ring-down amplitude nodes, cached per table ---------------------------------------------
# table → {ring-down inputs' bytes: (amplitudes A_q (n, q), weights c_q (n, q))}
_NODES: weakref.WeakKeyDictionary[MeasurementTable, dict[bytes, tuple[np.ndarray, np.ndarray]]] = (
    weakref.WeakKeyDictionary()
)


def cached_nodes(
    table: MeasurementTable, config: Configuration, start_rad: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude nodes of the table's ring-downs from ``start_rad``, cached per table and
    ring-down inputs (the inputs also come from the probe where the table has no column:
    Configuration.base; the start swings from the model's own rest angles)."""
    inputs = (config.theta0_rad, start_rad, config.ringdown_damping_per_s, config.ringdown_duration_s)
    key = b"".join(np.ascontiguousarray(values, float).tobytes() for values in inputs)
    cached = _NODES.setdefault(table, {})
    if key not in cached:
        cached[key] = ringdown_nodes(config, start_rad)
    return cached[key]
