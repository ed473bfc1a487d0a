"""Checking plain data (YAML mappings, arguments) into the arrays and numbers the physics uses.

Shared by the field sources, the coil setups, the fluxgates and the simulator scenarios: each
helper raises ValueError naming the offending key, so a bad file says what is wrong.
"""

from __future__ import annotations

import inspect
import os
import pathlib
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import yaml
from numpy.typing import ArrayLike

#: A number or an array of numbers: the physics works element-wise on either.
FloatOrArray = float | np.ndarray
#: A short vector of numbers, as a tuple or an array.
Vector = Sequence[float] | np.ndarray


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


def build_from_yaml(path: str | os.PathLike[str], what: str, builder: Callable[..., Any]) -> Any:
    """``builder(**mapping)`` of the YAML mapping in the file at ``path``, its keys checked
    (:func:`check_keys`); ValueError naming the file and what is wrong."""
    path = pathlib.Path(path)
    try:
        data = yaml.safe_load(path.read_text(encoding="utf-8"))
        if not isinstance(data, dict):
            raise ValueError(f"expected a mapping, got {data!r}")
        check_keys(what, data, builder)
        return builder(**data)
    except (OSError, yaml.YAMLError, ValueError, TypeError) as error:
        raise ValueError(f"{path}: {error}") from None
