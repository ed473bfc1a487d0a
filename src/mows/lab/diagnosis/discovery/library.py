"""The library the search beyond the catalog draws on: the rows' covariates (factors) and their
monomials up to degree 2, in physical units, as the search and the written plugins compute them.

The factors are the rows' covariates in the probe frame (:data:`FACTORS`): the reference field
B∥ = Bx', B⊥ = By', |B|, Bz and the gradient Gx'x', Gx'y', Gy'y'; temperature T, time t, coil
current I, the table's start swing ``amplitude_deg``; the model's own rest angle θs and start swing
at the reference in full (:func:`model_covariates`); and cos kθ0, sin kθ0 for k = 1…4. Only those
the table has, and not constant. Factors whose zero is arbitrary (extra columns) are centred on the
table's mean before they multiply, the temperature on the probe's reference temperature (where its
constants hold: a moment's temperature coefficient is then one term, not that and a scale error);
those with a physical zero (fields, current, swings, harmonics, and time from the table's start,
where the probe's constants were last known to hold) are not, so that coil heating is one term,
I², and not I² and I of a centred current, and a moment that ages is one term, m·t.

A monomial is a product of up to :data:`DEGREE` factors, without products of two angle harmonics
(that is another harmonic); each channel (:mod:`.channels`) takes the kinds of covariates it can
follow, and the physical ones the empty monomial 1.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence

import numpy as np

from mows.lab.data.probe_rows import ProbeSet, probe_parts
from mows.lab.data.table import KNOWN, LABELS, MAGNET, NEIGHBOUR, NOT_COVARIATES, MeasurementTable
from mows.lab.model.configuration import Configuration
from mows.lab.model.frequency_model import FrequencyModel
from mows.physics.potential import ArcPotential

DEGREE = 2  # products and squares of up to this many factors
HARMONICS = range(1, 5)  # cos kθ0, sin kθ0


@dataclasses.dataclass(frozen=True)
class Factor:
    """A covariate a term may hold: its kind (what the readings read), unit, and whether it is
    centred on the table's mean before it multiplies (no physical zero)."""

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


def factor(name: str) -> Factor:
    """The factor called ``name``: one of :data:`FACTORS`, else an extra column (centred)."""
    return next((f for f in FACTORS if f.name == name), Factor(name, "extra", f"[{name}]", centred=True))


def kinds(factors: Sequence[str]) -> tuple[str, ...]:
    """The sorted kinds of a monomial's factors (what the readings are keyed by)."""
    return tuple(sorted(factor(name).kind for name in factors))


def term_name(factors: Sequence[str]) -> str:
    """The factors joined by "·", a square as "x²", "1" for none: ``b_along_t·temperature_k``."""
    if len(factors) == 2 and factors[0] == factors[1]:
        return f"{factors[0]}²"
    return "·".join(factors) or "1"


def term_unit(factors: Sequence[str]) -> str:
    """The unit of a product of ``factors``: their units, a repeated one squared, "1" for none."""
    units = [factor(name).unit for name in factors if factor(name).unit != "1"]
    counted = [(unit, units.count(unit)) for unit in dict.fromkeys(units)]
    return "·".join(unit + ("²" if count == 2 else "") for unit, count in counted) or "1"


def per_unit(unit: str, of: str = "Hz") -> str:
    """``of`` per ``unit``: "Hz/K", "Hz/(T·K)", "Hz" for a unit of 1."""
    return of if unit == "1" else f"{of}/({unit})" if "·" in unit else f"{of}/{unit}"


def model_covariates(table: MeasurementTable, probes: ProbeSet) -> dict[str, np.ndarray]:
    """The model's rest angle θs and start swing of every row (rad), at the table's reference in
    full and the probe's stop, as :func:`mows.lab.model.frequency_model.table_start_swing_rad` takes
    them; ``table``'s own rows, each probe of a :class:`ProbeSet` with its constants."""
    found = {name: np.empty(len(table)) for name in MODEL_FACTORS}
    for rows, part, entry in probe_parts(table, probes):
        config = Configuration.base(part, entry.probe)
        _, field, gradient, _ = config.probe_frame()
        potential = ArcPotential.from_local_field(
            entry.probe, field, gradient, None, None, spring_nm_per_rad=config.spring_nm_per_rad
        )
        found["rest_angle_rad"][rows] = potential.rest_angle_rad()
        found["start_swing_rad"][rows] = config.start_swing_rad(potential)
    return found


def factor_values(table: MeasurementTable, probes: ProbeSet) -> dict[str, np.ndarray]:
    """Every factor the table has (:data:`FACTORS`, then its extra numeric columns), in physical
    units, centred where the factor has no physical zero; constant or non-finite ones left out."""
    derived = table.derived_columns()
    found = {name: derived[name] for name in DERIVED_FACTORS if name in derived}
    found.update({name: table.columns[name] for name in TABLE_FACTORS if table.has(name)})
    distinct, inverse = FrequencyModel(probes).groups(table)
    found.update({name: values[inverse] for name, values in model_covariates(distinct, probes).items()})
    theta0 = table.theta0_rad
    found.update({f"{trig}({k}θ0)": getattr(np, trig)(k * theta0) for k in HARMONICS for trig in ("cos", "sin")})
    found.update({name: values for name, values in table.columns.items() if name not in NOT_EXTRA})
    usable = {name: values for name, values in found.items() if np.isfinite(values).all() and np.ptp(values) > 0}
    centres = factor_centres(usable, probes)
    return {name: values - centres[name] if name in centres else values for name, values in usable.items()}


def factor_centres(factors: dict[str, np.ndarray], probes: ProbeSet) -> dict[str, float]:
    """What the centred factors are measured from: the temperature from the probe's reference
    temperature (where kM and m are given, so that a moment's temperature coefficient is one term
    and not a term and a moment-scale error), the others from the table's mean. Six digits: exact
    enough for a plugin's text (1e-6 of T moves a moment by c·3e-4 K)."""
    return {
        name: float(probes.first.reference_temperature_k if name == "temperature_k" else f"{np.mean(values):.6g}")
        for name, values in factors.items()
        if factor(name).centred
    }


def monomials(factors: dict[str, np.ndarray], excludes: frozenset[str], degree: int = DEGREE) -> list[tuple[str, ...]]:
    """The products of up to ``degree`` of ``factors`` but those of the kinds ``excludes``, at
    most one angle harmonic each; with the empty one, 1, where angle harmonics are excluded (else
    the monomials are an additive frequency's, and f00 is its 1)."""
    names = [name for name in factors if factor(name).kind not in excludes]
    found: list[tuple[str, ...]] = [()] if "angle" in excludes else []
    for size in range(1, degree + 1):
        for chosen in itertools.combinations_with_replacement(names, size):
            if sum(factor(name).kind == "angle" for name in chosen) <= 1:
                found.append(chosen)
    return found


def monomial_values(factors: dict[str, np.ndarray], chosen: Sequence[str], n: int) -> np.ndarray:
    """The monomial's values on the rows (n,): the product of its factors, 1 for none."""
    return np.prod([factors[name] for name in chosen], axis=0) if chosen else np.ones(n)


def factor_expression(name: str, means: dict[str, float]) -> str:
    """The physical value of a factor as a plugin computes it from ``rows``: a column, a harmonic,
    the model's rest angle or start swing, centred on the table's mean where the library centres it
    (a number, not ``rows.….mean()``: the model evaluates a plugin on a subset of rows at a time)."""
    if name.endswith("θ0)"):
        trig, k = name.split("(")
        return f"np.{trig}({k.removesuffix('θ0)')} * rows.theta0_rad)"
    if name in MODEL_FACTORS:
        return f'model_covariates(rows, PROBE)["{name}"]'
    if factor(name).centred:
        return f"(rows.{name} - {means[name]!r})"
    return f"rows.{name}"


def product_expression(factors: Sequence[str], means: dict[str, float]) -> str:
    """A monomial as a Python expression over ``rows`` ("1.0" for the empty one)."""
    if not factors:
        return "1.0"
    if len(factors) == 2 and factors[0] == factors[1]:
        return f"{factor_expression(factors[0], means)} ** 2"
    return " * ".join(factor_expression(name, means) for name in factors)
