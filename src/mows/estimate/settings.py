"""The fit settings of the estimator's parameters: the one path from the values of the estimator
node's parameters (``f00_hz``, ``channels``, ``sensor_*``, ``probes`` …) to the
:class:`mows.estimate.stream.FitSettings` of each ring-down, taken by the node and by the
offline commands that fit a recorded bag as the node would (``mows fit``, ``mows lab ringdown``).

:class:`FitParameters` holds those values under the parameters' names, with the parameters'
defaults; the node's parameter table takes its defaults from it and checks the values' ranges.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping, Sequence
from typing import Any

from mows.estimate.probe_set import ProbeEntry, WindowProbe, own_probe_entry, read_probe_set
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, ProbeLine
from mows.estimate.stream import FitSettings
from mows.physics.fluxgate import PAPER_DISTANCE_M, PAPER_SPACING_M, FluxgatePair
from mows.physics.probe import Probe


@dataclasses.dataclass(frozen=True)
class FitParameters:
    """The estimator's parameters that say how a ring-down is fitted and inverted, under their
    names (docs/nodes.md): f00 (0: the probe's), the channels fitted, the sensing axis (a, b),
    θ0 fitted or taken, the lever-aware pickup of the fluxgate pair ``sensor_distance_m`` from
    the probe along ``sensor_direction`` and ``sensor_spacing_m`` apart, the samples skipped
    after coil-off, the shortest usable ring-down, the χ²/dof refused, and the ``probes`` text
    of the probes told apart in each window (read by :func:`node_probes`)."""

    f00_hz: float = 0.0
    f00_std_hz: float = 0.0
    channels: str = FitOptions.channels
    sensor_axis_a: float = 0.0
    sensor_axis_b: float = 1.0
    theta0_free: bool = False
    lever_aware: bool = True
    sensor_distance_m: float = PAPER_DISTANCE_M
    sensor_direction: tuple[float, float, float] = (1.0, 0.0, 0.0)
    sensor_spacing_m: float = PAPER_SPACING_M
    coil_off_skip_s: float = COIL_OFF_SKIP_S
    min_periods: float = FitOptions.min_periods
    max_chi2_dof: float = FitOptions.max_chi2_dof
    probes: str = ""

    @classmethod
    def of(cls, values: Mapping[str, Any]) -> FitParameters:
        """The fields of ``values`` (a node's parameter values, others ignored)."""
        given = {field.name: values[field.name] for field in dataclasses.fields(cls)}
        return cls(**given | {"sensor_direction": tuple(float(x) for x in given["sensor_direction"])})

    def fluxgate_pair(self) -> FluxgatePair:
        """The pair the parameters describe, the probe at the origin of the rotation plane's frame."""
        return FluxgatePair.paper(
            distance_m=self.sensor_distance_m,
            spacing_m=self.sensor_spacing_m,
            direction=self.sensor_direction,
            axis=(self.sensor_axis_a, self.sensor_axis_b, 0.0),
        )

    def own_entry(self, probe: Probe) -> ProbeEntry:
        """The estimator's own probe (``probe_file``) as the set's probe 0, at the f00 the
        parameters give it (f00 = 0: the probe's)."""
        return own_probe_entry(probe, self.f00_hz, self.f00_std_hz)

    def fit_options(self, probes: Sequence[ProbeEntry]) -> FitOptions:
        """The fit's options for ``probes``: the rest offset searched within the narrowest of
        their housing stops."""
        return FitOptions(
            self.channels,
            sensor_direction=(self.sensor_axis_a, self.sensor_axis_b),
            theta0_free=self.theta0_free,
            min_periods=self.min_periods,
            max_chi2_dof=self.max_chi2_dof,
            theta_stop_rad=min(e.probe.theta_stop_rad for e in probes),
        )

    def lines(self, held: Sequence[WindowProbe]) -> list[ProbeLine]:
        """The lines of the probes a window holds (each known to the set), each at its own θ0:
        the lever-aware pickup of its magnet at its place where asked for and possible (θ0
        taken, one combined channel), else the paper's single term along the sensing axis.
        ValueError for what cannot be built (a sensing axis of (0, 0), θ0 fitted for several)."""
        if self.theta0_free and len(held) > 1:
            raise ValueError(f"theta0_free fits the θ0 of one probe; {len(held)} probes share this window")
        lever_aware = self.lever_aware and not self.theta0_free and self.channels != "both"
        pair = self.fluxgate_pair() if lever_aware else None
        return [p.entry.line(p.theta0_rad, pair, self.channels, p.tone_hz) for p in held if p.entry is not None]

    def fit_settings(self, probe: Probe) -> FitSettings:
        """What the parameters ask of each ring-down's fit and inversion."""
        probes = node_probes(self.probes, self.own_entry(probe))
        return FitSettings(probes, self.lines, self.fit_options(probes), self.coil_off_skip_s)


@functools.lru_cache(maxsize=8)
def probe_set(text: str, own_probe: Probe) -> tuple[ProbeEntry, ...]:
    """The probes of a ``probes`` value (:func:`mows.estimate.probe_set.read_probe_set`, probe
    files read by :meth:`Probe.from_yaml`), with ``own_probe`` for those given by their f00
    alone; read once per value and probe, not per fit."""
    return read_probe_set(text, own_probe, Probe.from_yaml)


def node_probes(text: str, own: ProbeEntry) -> tuple[ProbeEntry, ...]:
    """The probes a node tells apart, read once from its ``probes`` value, never none: those it
    lists (:func:`probe_set`, those given by f00 alone ``own``'s probe at that f00), and for a
    value that lists none ``own``, the node's own probe as probe 0, a set of one. Whatever reads
    them after this takes one path for one probe and for several. ValueError naming what is
    wrong in ``text``."""
    return probe_set(text, own.probe) or (own,)
