"""Checking plain data (YAML mappings, arguments) into the arrays and numbers the physics uses.

Shared by the field sources, the coil setups, the fluxgates and the simulator scenarios: each
helper raises ValueError naming the offending key, so a bad file says what is wrong.
"""

from __future__ import annotations

import inspect
import os
import pathlib
import typing
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np
import yaml
from numpy.typing import ArrayLike

#: A number or an array of numbers: the physics works element-wise on either.
FloatOrArray = float | np.ndarray
#: A short vector of numbers, as a tuple or an array.
Vector = Sequence[float] | np.ndarray
T = TypeVar("T")


def as_points_m(points_m: ArrayLike) -> np.ndarray:
    """``points_m`` as a float array of shape (..., 3); ValueError otherwise."""
    points = np.asarray(points_m, dtype=float)
    if points.ndim == 0 or points.shape[-1] != 3:
        raise ValueError(f"points_m must have shape (..., 3), got shape {points.shape}")
    return points


def vector3(name: str, value: ArrayLike) -> np.ndarray:
    """A finite, read-only 3-vector."""
    vector = np.array(value, dtype=float)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise ValueError(f"{name} must be a finite 3-vector, got {value!r}")
    vector.setflags(write=False)
    return vector


def unit_vector3(name: str, value: ArrayLike) -> np.ndarray:
    """A read-only unit 3-vector along ``value``."""
    vector = vector3(name, value)
    norm = np.linalg.norm(vector)
    if norm == 0.0:
        raise ValueError(f"{name} must be a non-zero 3-vector, got {value!r}")
    unit = vector / norm
    unit.setflags(write=False)
    return unit


def positive(name: str, value: float) -> float:
    """``value`` as a finite float > 0."""
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def plain(value: Any) -> Any:
    """``value`` as YAML-ready Python floats and lists."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    return float(value) if isinstance(value, (float, np.floating)) else value


def check_keys(what: str, given: dict, builder: Callable[..., Any]) -> None:
    """ValueError unless ``given`` holds every required argument of ``builder`` and no other."""
    parameters = inspect.signature(builder).parameters
    unknown = sorted(set(given) - set(parameters))
    missing = [k for k, p in parameters.items() if p.default is inspect.Parameter.empty and k not in given]
    if unknown or missing:
        raise ValueError(f"{what}: unknown keys {unknown}, missing keys {missing}; allowed keys are {list(parameters)}")


def build_from_yaml(path: str | os.PathLike[str], what: str, cls: type[T], **convert: Callable[[Any], Any]) -> T:
    """The dataclass ``cls`` of the YAML mapping in the file at ``path`` (:func:`typed`);
    ValueError naming the file and what is wrong."""
    path = pathlib.Path(path)
    try:
        return typed(cls, what, yaml.safe_load(path.read_text(encoding="utf-8")), **convert)
    except (OSError, yaml.YAMLError, ValueError, TypeError) as error:
        raise ValueError(f"{path}: {error}") from None


def typed(cls: type[T], what: str, given: Any, **convert: Callable[[Any], Any]) -> T:
    """The dataclass ``cls`` of the mapping ``given`` (a YAML section called ``what``), its keys
    checked (:func:`check_keys`): each value through ``convert[key]`` where there is one, else
    made the float, int or str its field is declared as (YAML reads ``1`` as an int, ``1e-4``
    as a str). ValueError naming ``what`` for anything else than a mapping."""
    if not isinstance(given, dict):
        raise ValueError(f"{what} must be a mapping, got {given!r}")
    check_keys(what, given, cls)
    declared = typing.get_type_hints(cls)
    return cls(**{key: _as_declared(key, declared[key], value, convert.get(key)) for key, value in given.items()})


def _as_declared(key: str, declared: Any, value: Any, convert: Callable[[Any], Any] | None) -> Any:
    if convert is not None:
        return convert(value)
    if declared not in (float, int, str):
        return value
    try:
        return declared(value)
    except (TypeError, ValueError):
        raise ValueError(f"{key} = {value!r} is not a {declared.__name__}") from None
