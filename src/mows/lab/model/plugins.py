"""Plugins: effects a user writes, in Python files or installed packages (entry points).

A plugin file defines effects with the :func:`effect` decorator::

    from mows.lab import effect

    @effect(name="coil_heating", parameters={"k_per_a2_nm_per_rad": (0.0, -1e-5, 1e-5, "N·m/rad/A²")},
            explanation="...", signature="grows with coil current squared")
    def coil_heating(rows, k_per_a2_nm_per_rad):
        return {"stiffness_nm_per_rad": k_per_a2_nm_per_rad * rows.coil_current_a ** 2}

A function ``(rows, probe, …)`` also gets the probe's constants (a
:class:`mows.physics.probe.Probe`: ``probe.moment_am2``, ``probe.lever_m`` …; with several probes in
the table, each probe's rows with its own).

A plugin returns a dict of per-row changes (each a number or one per row). The physical ones go
through the full potential U(θ) (docs/physics.md §4, §6: exact rest angle, start swing and harmonic
balance), so they compose with every other effect at any field:

====================================  =======================================================
``moment_scale``                      relative change of the moment m: m → m·(1 + value)
``stiffness_nm_per_rad``              added to kM: U gains ½·Δk·θ²
``field_offset_t``                    in-plane field (bx, by) or (bx, by, bz), global frame, T,
                                      added to the reference field
``tilt_rad``                          small rotations (about x, about y) of the reference field
                                      and gradient into the plane, rad
``angle_offset_rad``                  added to the probe's orientation θ0, rad
``magnet_offset_m``                   the magnet's position from (l, 0, 0) in the lever's frame,
                                      (along, across) or (along, across, normal), m; it turns
                                      with the lever, the moment stays along it
``pivot_offset_m``                    the pivot's position from where the reference puts it,
                                      (x, y) or (x, y, z), global frame, m
``frequency_hz``                      added to f after the potential (a readout term, no physics)
``energy_j``                          a function ``energy(arc) -> U_user`` (J, per row and
                                      deflection): energy added to U(θ). ``arc`` is a
                                      :class:`mows.lab.model.configuration.LeverArc`: the
                                      deflections θ, the moment's direction u(θ), the magnet's
                                      displacement and the field there, per row. Any mechanical
                                      or magnetic effect is the energy it adds.
====================================  =======================================================

The reference field and gradient are given at the magnet's nominal position; moved magnets and
pivots feel them through the field's expansion B + G·δr + ½·H:δr δr
(:func:`mows.physics.potential.arc_displacement_m`).

An induced moment (a soft-magnetic part magnetised by the field along it) adds
U = −½·α·(u·B)²::

    @effect(name="induced_moment", parameters={"alpha_am2_per_t": (0.0, -1e-2, 1e-2, "A·m²/T")})
    def induced_moment(rows, alpha_am2_per_t):
        return {"energy_j": lambda arc: -0.5 * alpha_am2_per_t * ((arc.field_t * arc.direction).sum(-1)) ** 2}

Rows expose the table's columns and the reference in the probe frame
(:meth:`mows.lab.data.table.MeasurementTable.derived_columns`: ``rows.b_along_t``, ``rows.b_perp_t``,
``rows.g_t_per_m`` …), every covariate the lab names in its hints. A moment that falls with
temperature is ``{"moment_scale": c_per_k * (rows.temperature_k - t_ref_k)}`` (docs/model_lab.md).
Installed packages register effects under the entry-point group ``mows.lab.effects``.
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import inspect
import pathlib
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from mows.lab.data.table import MeasurementTable, MissingColumnError
from mows.lab.model.configuration import Configuration, LeverArc, rotation_matrix
from mows.lab.model.effects import MECHANICS, Effect, Parameter
from mows.physics.potential import LOCAL_NODES
from mows.physics.probe import Probe

ENTRY_POINT_GROUP = "mows.lab.effects"
# What a plugin may return: name → the trailing shape of one row's value.
OUTPUTS = {
    "moment_scale": (),
    "stiffness_nm_per_rad": (),
    "field_offset_t": (3,),
    "tilt_rad": (2,),
    "angle_offset_rad": (),
    "magnet_offset_m": (3,),
    "pivot_offset_m": (3,),
    "frequency_hz": (),
    "energy_j": (LOCAL_NODES,),
}
VECTORS = ("field_offset_t", "magnet_offset_m", "pivot_offset_m")  # two components gain a third, 0
PROBE_ARGUMENT = "probe"  # a plugin function's argument after ``rows`` that receives the probe
# How far from nothing an output may be with every parameter at its off value (rounding of the
# user's own arithmetic), relative to its natural size on the probe (:func:`_off_scales`).
OFF_TOLERANCE = 1e-9


def effect(
    name: str,
    parameters: dict[str, tuple[float, float, float, str]],
    explanation: str = "",
    signature: str = "",
    equation: str = "",
    check: str = "",
) -> Callable[[Callable[..., dict[str, Any]]], Effect]:
    """Decorator turning ``function(rows, **parameters) -> dict`` (or ``function(rows, probe,
    **parameters)``) into an :class:`Effect`.

    ``parameters`` maps each name to ``(off_value, lower, upper, unit)``: the effect is absent
    at the off value (usually 0; a stiffness, say, is off at the spring the model already has),
    which lies within the bounds. The function receives the table (columns as attributes), the
    probe where it asks for it, and the parameter values, and returns a dict of the changes in
    the module docstring's table (scalars or per-row arrays); at the off values they must be
    nothing (0, and an energy flat in θ).
    """
    specs = [_parameter(name, pname, spec) for pname, spec in parameters.items()]

    def decorate(function: Callable[..., dict[str, Any]]) -> Effect:
        accepted = list(inspect.signature(function).parameters)[1:]
        takes_probe = accepted[:1] == [PROBE_ARGUMENT]
        if accepted[takes_probe:] != [p.name for p in specs]:
            raise ValueError(
                f"effect {name}: the function takes {accepted}, the parameters are {[p.name for p in specs]} "
                f"(after rows and, if it wants the probe's constants, {PROBE_ARGUMENT})"
            )

        where = f"plugin effect {name} ({function.__code__.co_filename})"
        offs = tuple(p.off for p in specs)

        def apply(config: Configuration, rows: MeasurementTable, probe: Probe, *values: float) -> None:
            called = ", ".join(f"{p.name}={v:.6g}" for p, v in zip(specs, values))
            try:
                result = function(rows, probe, *values) if takes_probe else function(rows, *values)
            except MissingColumnError:
                raise
            except Exception as error:  # the plugin's bug is the user's input: say whose and where
                raise ValueError(f"{where} raised {type(error).__name__}: {error} (called with {called})") from error
            if not isinstance(result, dict):
                raise ValueError(f"{where} returned {type(result).__name__}, not a dict of {', '.join(OUTPUTS)}")
            unknown = set(result) - set(OUTPUTS)
            if unknown:
                raise ValueError(f"effect {name} returned {sorted(unknown)}; allowed: {', '.join(OUTPUTS)}")
            n = len(config.theta0_rad)
            if "energy_j" in result:
                result["energy_j"] = _energy_at_nodes(where, result["energy_j"], config, probe, called)
            changes = {key: _finite_values(where, key, value, n, called) for key, value in result.items()}
            if values == offs:
                _require_nothing(where, changes, probe, called)
            _apply_outputs(config, changes)

        return Effect(
            name,
            explanation or function.__doc__ or name,
            equation,
            signature,
            tuple(specs),
            apply,
            MECHANICS,
            requires=(),
            priority=200,
            check=check,
            origin=function.__module__,
        )

    return decorate


def _parameter(effect_name: str, name: str, spec: tuple[float, float, float, str]) -> Parameter:
    """The :class:`Parameter` of a plugin's ``(off_value, lower, upper, unit)``."""
    if name == PROBE_ARGUMENT:
        raise ValueError(f"effect {effect_name}: '{PROBE_ARGUMENT}' is the probe's argument, not a parameter name")
    try:
        off, lower, upper, unit = spec
        values = float(off), float(lower), float(upper)
    except (TypeError, ValueError):
        raise ValueError(f"effect {effect_name}: parameter {name} needs (off_value, lower, upper, unit)") from None
    if not (values[1] <= values[0] <= values[2] and values[1] < values[2]):
        raise ValueError(
            f"effect {effect_name}: parameter {name} needs lower ≤ off value ≤ upper and lower < upper "
            f"(got off {off}, bounds {lower} … {upper})"
        )
    return Parameter(name, unit, values[1], values[2], (values[2] - values[1]) * 1e-3, off=values[0])


def _off_scales(probe: Probe) -> dict[str, float]:
    """Each output's natural size on ``probe``: what "nothing" is measured against."""
    field_t = probe.spring_nm_per_rad / probe.moment_am2  # the field that doubles the spring
    return {
        "moment_scale": 1.0,
        "stiffness_nm_per_rad": probe.spring_nm_per_rad,
        "field_offset_t": field_t,
        "tilt_rad": 1.0,
        "angle_offset_rad": 1.0,
        "magnet_offset_m": probe.lever_m,
        "pivot_offset_m": probe.lever_m,
        "frequency_hz": probe.f00_hz,
        "energy_j": probe.spring_nm_per_rad,
    }


def _require_nothing(where: str, changes: dict[str, np.ndarray], probe: Probe, called: str) -> None:
    """ValueError unless a plugin's ``changes`` at its off values change nothing: the lab tests an
    effect from there (score tests, refits), so an effect that is not absent at its off values
    would be a different model."""
    scales = _off_scales(probe)
    for key, values in changes.items():
        size = np.ptp(values, axis=-1) if key == "energy_j" else values  # a constant energy does nothing
        if np.max(np.abs(size), initial=0.0) > OFF_TOLERANCE * scales[key]:
            raise ValueError(
                f"{where} returned {key} up to {np.max(np.abs(size)):.3g} with {called}: at its parameters' "
                "off values an effect must change nothing (declare the off value at which it does)"
            )


def _apply_outputs(config: Configuration, changes: dict[str, np.ndarray]) -> None:
    """Edit the configuration by a plugin's per-row ``changes`` (module docstring)."""
    if "tilt_rad" in changes:
        rotations = np.array([rotation_matrix((tx, ty, 0.0)) for tx, ty in changes["tilt_rad"]])
        config.field_t = np.einsum("nij,nj->ni", rotations, config.field_t)
        config.gradient_t_per_m = np.einsum("nai,nij,nbj->nab", rotations, config.gradient_t_per_m, rotations)
    if "field_offset_t" in changes:
        config.field_t = config.field_t + changes["field_offset_t"]
    if "moment_scale" in changes:
        config.moment_factor = config.moment_factor * (1.0 + changes["moment_scale"])
    for key in ("magnet_offset_m", "pivot_offset_m"):
        if key in changes:
            before = getattr(config, key)
            setattr(config, key, changes[key] + (0.0 if before is None else before))
    if "energy_j" in changes:
        config.energy_j = changes["energy_j"] + (0.0 if config.energy_j is None else config.energy_j)
    config.theta0_rad = config.theta0_rad + changes.get("angle_offset_rad", 0.0)
    config.spring_nm_per_rad = config.spring_nm_per_rad + changes.get("stiffness_nm_per_rad", 0.0)
    config.frequency_hz = config.frequency_hz + changes.get("frequency_hz", 0.0)


def _energy_at_nodes(where: str, energy: object, config: Configuration, probe: Probe, called: str) -> object:
    """A plugin's ``energy_j`` function evaluated along the lever's arc (:class:`LeverArc`)."""
    if not callable(energy):
        raise ValueError(f"{where} returned energy_j = {energy!r}: expected a function of the lever's arc (LeverArc)")
    try:
        return energy(LeverArc.of(config, probe))
    except Exception as error:  # the plugin's bug is the user's input: say whose and where
        raise ValueError(f"{where}'s energy_j raised {type(error).__name__}: {error} (called with {called})") from error


def _finite_values(where: str, key: str, value: object, n: int, called: str) -> np.ndarray:
    """A plugin's returned ``key`` as n finite values of its shape (OUTPUTS), or why not; an
    in-plane vector (VECTORS) gains a third component 0."""
    shape = OUTPUTS[key]
    try:
        values = np.asarray(value, dtype=float)
        if key in VECTORS and values.shape[-1:] == (2,):
            values = np.concatenate([values, np.zeros(values.shape[:-1] + (1,))], axis=-1)
        values = np.broadcast_to(values, (n, *shape))
    except (TypeError, ValueError):
        per_row = f"{shape[0]} numbers" if shape else "a number"
        raise ValueError(f"{where} returned {key} = {value!r}: expected {per_row} or one such per row ({n})") from None
    bad = np.flatnonzero(~np.isfinite(values).reshape(n, -1).all(-1))
    if bad.size:
        raise ValueError(
            f"{where} returned NaN or infinite {key} in {bad.size} of {n} rows (first: row {bad[0] + 1}) "
            f"with {called}: an effect must return finite numbers"
        )
    return values


def load_plugins(sources: Iterable[str | pathlib.Path]) -> list[Effect]:
    """Effects from plugin files (``*.py`` paths) or installed entry points (group
    ``mows.lab.effects``, by entry-point name). A file contributes every :class:`Effect` it
    defines at module level."""
    found = []
    for source in sources:
        path = pathlib.Path(source)
        if path.suffix == ".py" or path.exists():
            found.extend(_effects_in_file(path))
            continue
        points = [p for p in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP) if p.name == source]
        if not points:
            raise ValueError(f"plugin '{source}' is neither a .py file nor an entry point in group {ENTRY_POINT_GROUP}")
        loaded = points[0].load()
        found.extend([loaded] if isinstance(loaded, Effect) else _effects_in(vars(loaded), source))
    return found


def _effects_in_file(path: pathlib.Path) -> list[Effect]:
    if not path.is_file():
        raise ValueError(f"plugin file {path} does not exist")
    spec = importlib.util.spec_from_file_location(f"mows_lab_plugin_{path.stem}", path)
    if spec is None or spec.loader is None:  # a file Python has no loader for (not a .py)
        raise ValueError(f"plugin file {path} is not a Python file")
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as error:  # a broken plugin is the user's error: say where
        raise ValueError(f"plugin file {path} failed to load: {type(error).__name__}: {error}") from error
    return _effects_in(vars(module), path)


def _effects_in(namespace: dict[str, object], source: str | pathlib.Path) -> list[Effect]:
    effects = [value for value in namespace.values() if isinstance(value, Effect)]
    if not effects:
        raise ValueError(f"plugin {source} defines no effect (use the @mows.lab.effect decorator)")
    return effects
