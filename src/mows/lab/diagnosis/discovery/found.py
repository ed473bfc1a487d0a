"""What the search beyond the catalog found: the terms, each with its channel, reading, the
readings that fit as well, and the plugin that writes it; and the report's lines."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.lab.diagnosis.discovery.library import DEGREE, per_unit
from mows.lab.model.effects import Effect
from mows.lab.model.least_squares import FittedParameter
from mows.records.json_numbers import finite_or_none


@dataclasses.dataclass(frozen=True)
class TermFit:
    """What a term's strength is fitted to, row by row on the rows searched (a picture's numbers):
    the term beyond what the model absorbs (its weighted column projected off the model's
    Jacobian, over the row's weight w = 1/σ: Hz per unit of the term's parameter) and the residual
    it explains (the weighted residual less the other kept terms' fits, over w: Hz), with each
    row's σ (Hz). The weighted least-squares slope of ``residual_hz`` on ``beyond_model`` is the
    term's strength."""

    beyond_model: np.ndarray
    residual_hz: np.ndarray
    std_hz: np.ndarray


@dataclasses.dataclass
class DiscoveredTerm:
    """A term the residual follows beyond the catalog: a channel of the potential times a
    monomial of the covariates (:mod:`mows.lab.diagnosis.discovery.channels`)."""

    name: str  # "channel × monomial", e.g. "moment × temperature_k", "spring × coil_current_a²"
    channel: str  # the channel it acts in (moment, spring, field_x, …, frequency)
    factors: tuple[str, ...]  # the monomial's factors (none: the channel alone)
    family: str  # the channel and the monomial's kinds, e.g. "moment_temperature"
    strength: float  # the channel's parameter per unit of the monomial
    std: float  # its σ
    selection_frequency: float  # fraction of the half-samples that kept it
    cv_gain_chi2: float  # held-out χ² without minus with the term
    reading: str  # its physical reading in words
    plugin: str  # the plugin file's source that writes it in its channel
    unit: str = "1"  # the monomial's unit
    channel_unit: str = "Hz"  # the channel's parameter's unit
    p_value: float = math.nan  # of Δχ²/φ ~ χ²(1), before the Bonferroni factor
    aliases: tuple[str, ...] = ()  # library terms identical to it on these rows
    alternatives: tuple[str, ...] = ()  # readings of other channels that fit as well, and how to tell
    plugin_parameter: FittedParameter | None = None  # the plugin's parameter fitted on this table
    plugin_output: str = "frequency_hz"  # the plugin output that writes it
    plugin_line: str = ""  # the plugin on one line, for explanations
    effect_name: str = ""  # the plugin's effect (and file) name
    last_resort: str = ""  # why the plugin is the additive frequency term, if it is ("" if not)
    fitted: TermFit | None = dataclasses.field(default=None, compare=False, repr=False)

    @property
    def strength_unit(self) -> str:
        return per_unit(self.unit, self.channel_unit)

    def text(self) -> str:
        """One line: name, strength ± σ, stability, gain, reading."""
        alias = f" (on these rows the same as {', '.join(self.aliases[:3])})" if self.aliases else ""
        return (
            f"{self.name}{alias} ({self.strength:+.4g} ± {self.std:.2g} {self.strength_unit}, selected in "
            f"{100 * self.selection_frequency:.0f}% of the half-samples, held-out χ² −{self.cv_gain_chi2:.1f}; "
            f"{self.family}: {self.reading})"
        )

    def to_dict(self) -> dict:
        found = dataclasses.asdict(dataclasses.replace(self, fitted=None))
        del found["fitted"]
        found["factors"], found["aliases"] = list(self.factors), list(self.aliases)
        found["alternatives"] = list(self.alternatives)
        found["strength_unit"] = self.strength_unit
        found["plugin_parameter"] = (
            None
            if self.plugin_parameter is None
            else {"name": self.plugin_parameter.name, **self.plugin_parameter.to_dict()}
        )
        return finite_or_none(found)


@dataclasses.dataclass
class Discovery:
    """What :func:`mows.lab.diagnosis.discovery.discover` found: the terms, best first, and how
    hard it looked."""

    terms: list[DiscoveredTerm]
    library: int  # terms searched
    resamples: int
    degree: int
    summary: str  # one or two sentences for the report
    on_model: str = ""  # the model whose residual was searched
    # The terms in their channels with free strengths: a stand-in for the physics outside the
    # catalog, beside which the search judges catalog effects.
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
        """The text report's lines: what was searched, one line per term with the readings that
        fit as well, the strongest's plugin file (the file alone: ``mows lab add --save-plugin``)."""
        head = f"discovery beyond the catalog, on {self.on_model}:"
        if not self.terms:
            return [head, "  " + self.summary]
        found = [head + f" {self.library} channel terms up to degree {self.degree}, {self.resamples} half-samples"]
        for i, term in enumerate(self.terms, 1):
            found.append(f"  {i}. {term.text()}")
            found += [f"     or {alternative}" for alternative in term.alternatives]
            if term.last_resort:
                found.append(f"     written as an additive frequency, the last resort: {term.last_resort}")
        strongest = self.terms[0]
        found.append(
            f"  plugin for the strongest, in its channel ({strongest.channel}), to save as {strongest.effect_name}.py:"
        )
        return found + ["    " + line if line else "" for line in strongest.plugin.splitlines()]


def summary(terms: list[DiscoveredTerm], library_size: int, resamples: int, stable_fraction: float) -> str:
    """One or two sentences: how the search looked and what it found."""
    how = (
        f"A sparse search of {library_size} terms (each channel of the potential — moment, spring, field in the "
        f"lab and probe frames, angle, added energy, and last an additive frequency — times the rows' covariates, "
        f"their products and squares up to degree {DEGREE}, each beyond what the model absorbs; kept when selected "
        f"in ≥ {100 * stable_fraction:.0f}% of {resamples} half-samples, significant after Bonferroni and "
        "cross-validated)"
    )
    if not terms:
        return how + " finds no term."
    listed = "; ".join(term.text() for term in terms)
    return f"{how} finds {len(terms)} term{'s' if len(terms) > 1 else ''}: {listed}."
