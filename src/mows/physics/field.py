"""Static magnetic field sources in free space, consistent with Maxwell's equations: all of them
in one import, and their YAML form.

Sources: :class:`UniformField`, :class:`LinearGradient`, :class:`PointDipole`
(:mod:`mows.physics.sources`, with the conventions every source follows), :class:`CurrentLoop`
(exact, complete elliptic integrals) and what is built from loops (:func:`helmholtz_pair`,
:func:`anti_helmholtz_pair`, :func:`solenoid`; :mod:`mows.physics.loops`).
:func:`source_from_dict` and :func:`source_to_dict` give the YAML form, SI only::


    {type: uniform, field_t: [bx, by, bz]}
    {type: linear_gradient, gradient_t_per_m: [[..], [..], [..]], origin_m: [..], field_at_origin_t: [..]}
    {type: dipole, moment_am2: [..], position_m: [..]}
    {type: loop, center_m: [..], axis: [..], radius_m: r, turns: n, current_a: i}
    {type: helmholtz | anti_helmholtz, center_m, axis, radius_m, turns, current_a}
    {type: solenoid, center_m, axis, radius_m, length_m, turns, current_a, n_loops}

Helmholtz pairs and solenoids are sums of loops, and :func:`source_to_dict` writes them so.
"""

from __future__ import annotations

from collections.abc import Callable

from mows.physics.loops import CurrentLoop, anti_helmholtz_pair, helmholtz_pair, solenoid
from mows.physics.schema import check_keys, plain
from mows.physics.sources import (
    MU0,
    MU0_OVER_4PI,
    FieldSource,
    LinearGradient,
    PointDipole,
    SumSource,
    UniformField,
    dipole_field_t,
)

__all__ = [
    "MU0",
    "MU0_OVER_4PI",
    "CurrentLoop",
    "FieldSource",
    "LinearGradient",
    "PointDipole",
    "SumSource",
    "UniformField",
    "anti_helmholtz_pair",
    "dipole_field_t",
    "helmholtz_pair",
    "solenoid",
    "source_from_dict",
    "source_to_dict",
]


def _sum_of(sources: object) -> SumSource:
    if not isinstance(sources, (list, tuple)):
        raise ValueError(f"sources of a sum must be a list of source mappings, got {sources!r}")
    return SumSource(source_from_dict(s) for s in sources)


_BUILDERS: dict[str, Callable[..., FieldSource]] = {
    "uniform": UniformField,
    "linear_gradient": LinearGradient,
    "dipole": PointDipole,
    "loop": CurrentLoop,
    "helmholtz": helmholtz_pair,
    "anti_helmholtz": anti_helmholtz_pair,
    "solenoid": solenoid,
    "sum": _sum_of,
}


def source_from_dict(d: dict) -> FieldSource:
    """Build a source from its YAML mapping (module header); ValueError naming what is wrong."""
    if not isinstance(d, dict):
        raise ValueError(f"a field source must be a mapping, got {d!r}")
    kind = d.get("type")
    if kind not in _BUILDERS:
        raise ValueError(f"field source type {kind!r} is not one of {sorted(_BUILDERS)}")
    given = {k: v for k, v in d.items() if k != "type"}
    check_keys(f"field source {kind!r}", given, _BUILDERS[kind])
    return _BUILDERS[kind](**given)


def source_to_dict(source: FieldSource) -> dict:
    """The YAML mapping of ``source`` (pairs and solenoids come out as sums of loops)."""
    params = source._params()
    if isinstance(source, SumSource):
        return {"type": "sum", "sources": [source_to_dict(s) for s in source.sources]}
    return {"type": source.type_name, **{k: plain(v) for k, v in params.items()}}
