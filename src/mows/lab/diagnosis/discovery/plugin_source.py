"""The plugin file a term beyond the catalog is written as: its channel's output, the monomial's
expression over the rows, and one parameter (docs/model_lab.md, "Plugins").

A term p·x in a channel (:mod:`.channels`) becomes ``{output: p * x}`` in that channel's form
(a moment scale, a stiffness, a field offset in the lab or the probe frame, an angle offset, the
energy it adds along the lever's arc), so that the lab evaluates it through the exact potential
with every other effect: added back with ``--plugin``, it composes at any field. Where the plugin
interface has no output for the channel, the term is written as the additive frequency term and
the plugin's text says so: that is the last resort, not physics.
"""

from __future__ import annotations

import dataclasses
import math
import textwrap

from mows.lab.data.probe_rows import ProbeSet
from mows.lab.diagnosis.discovery.channels import Channel
from mows.lab.diagnosis.discovery.library import per_unit, product_expression, term_name, term_unit
from mows.lab.model.effects import Effect
from mows.lab.model.plugins import OUTPUTS

WHY = {
    "moment_scale": "the moment changes with it, in every magnetic term of the potential",
    "stiffness_nm_per_rad": "the spring changes with it",
    "field_offset_t": "a field the reference misses, through the potential",
    "tilt_rad": "the plane's tilt turns Bz into the plane",
    "angle_offset_rad": "the probe's angle changes with it, before the field is projected",
    "magnet_offset_m": "the magnet's position on the lever changes with it: it feels the gradient elsewhere",
    "energy_j": "the energy it adds to U(θ) along the lever's arc, through the potential",
    "frequency_hz": "an additive frequency term (a readout term, no physics); better the physics that makes it",
}


def writable(channel: Channel) -> bool:
    """The plugin interface has the channel's output."""
    return channel.output in OUTPUTS


def plugin_name(channel: Channel, factors: tuple[str, ...]) -> str:
    """A Python identifier for the effect of a term: ``discovered_``, the channel, its factors."""
    words = [name.replace("θ0)", "theta0").replace("(", "") for name in factors]
    if len(words) == 2 and words[0] == words[1]:
        words[1] = "squared"
    return "_".join(["discovered", channel.name, *words])


@dataclasses.dataclass(frozen=True)
class Plugin:
    """A term's plugin: its channel (the one written), factors, the monomial's centres, the
    parameter's bound, the probe (for the model's own covariates) and words; :meth:`source` is
    the file."""

    channel: Channel
    factors: tuple[str, ...]
    means: dict[str, float]
    bound: float
    probes: ProbeSet
    reading: str
    note: str = ""

    @property
    def name(self) -> str:
        return plugin_name(self.channel, self.factors)

    @property
    def unit(self) -> str:
        return per_unit(term_unit(self.factors), self.channel.unit)

    def value(self) -> str:
        """p·x as an expression over ``rows``."""
        parameter = self.channel.parameter
        return f"{parameter} * {product_expression(self.factors, self.means)}" if self.factors else parameter

    def returned(self) -> str:
        return f'{{"{self.channel.output}": {self.channel.returned.format(value=self.value())}}}'

    def imports(self) -> list[str]:
        found = ["import numpy as np"] if "np." in self.returned() else []
        found.append("from mows.lab import effect")
        if "PROBE" in self.returned():
            found += _probe_source(self.probes)
        return found

    def parameters(self) -> str:
        bound = float(self.bound)  # a plain number in the text, whatever type it came as
        return f'{{"{self.channel.parameter}": (0.0, {-bound!r}, {bound!r}, "{self.unit}")}}'

    def source(self) -> str:
        """The plugin file."""
        why = WHY[self.channel.output]
        imports = self.imports()
        found = (
            "the model lab's search beyond its catalog: the residual followed "
            f"{self.channel.name} × {term_name(self.factors)}"
        )
        words = (
            f"{self.reading[0].upper() + self.reading[1:]}, found by {found}. Written as {self.channel.output}: {why}."
        )
        return "\n".join(
            [
                '"""' + textwrap.fill(words + self.note, 96, break_long_words=False, break_on_hyphens=False),
                '"""',
                "",
                *(imports[:1] + [""] + imports[1:] if imports[0].startswith("import") else imports),
                "",
                "",
                "@effect(",
                f'    name="{self.name}",',
                f"    parameters={self.parameters()},",
                f'    explanation="{self.reading}: {why}",',
                f'    signature="follows {self.channel.name} × {term_name(self.factors)}",',
                ")",
                f"def {self.name}(rows, {self.channel.parameter}):",
                f"    return {self.returned()}",
                "",
            ]
        )

    def line(self) -> str:
        """The plugin on one line, for an explanation."""
        return (
            f'{"; ".join(self.imports())}; @effect(name="{self.name}", parameters={self.parameters()}) '
            f"def {self.name}(rows, {self.channel.parameter}): return {self.returned()}"
        )


def _probe_source(probes: ProbeSet) -> list[str]:
    """Lines that build ``PROBE`` (the analysis's probe constants) for a plugin reading the model's own θs or swing."""
    lines = ["from mows.lab.diagnosis.discovery import model_covariates", "from mows.physics.probe import Probe"]
    members = ", ".join(f"{e.probe_id}: Probe.from_dict({e.probe.to_dict()!r})" for e in probes.members)
    built = f"PROBE = ProbeSet.of({{{members}}}, column={probes.column})"
    return lines + ["from mows.lab.data.probe_rows import ProbeSet", "", built]


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
