"""Our YAML files (probe files, scenarios, the estimator's ``probes`` text, reference fields, the
card's device file, the supply file) read by one loader and checked into the dataclasses, arrays
and numbers the physics uses.

:func:`load_yaml` reads a file once, with YAML 1.2's numbers (:class:`NumberLoader`), and hands
the data to the format's builder; whatever the builder refuses is a ValueError on one line that
names the file. A refusal names where in the file the value sits: :class:`SchemaError` carries
the key path (``probes[2].position_m``) and the value, and :func:`at` adds a key to it on the
way out of a mapping or list (``scene.yaml: probes[2].position_m = [...] must be …``).
:func:`typed` checks a mapping into a dataclass of finite floats, integers and texts.
"""

from __future__ import annotations

import contextlib
import inspect
import os
import re
import typing
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

import numpy as np
import yaml
from numpy.typing import ArrayLike

from mows.records.files import read_input

#: A number or an array of numbers: the physics works element-wise on either.
FloatOrArray = float | np.ndarray
#: A short vector of numbers, as a tuple or an array.
Vector = Sequence[float] | np.ndarray
T = TypeVar("T")


class NumberLoader(yaml.SafeLoader):
    """PyYAML's safe loader with YAML 1.2's floats: ``1e-8``, ``-2E+3`` and ``.5e-3`` are numbers
    (YAML 1.1, which PyYAML follows, wants a dot before the exponent and reads them as text). A
    quoted number stays text. A key given twice in one mapping is refused (YAML 1.2 forbids it;
    PyYAML would keep the last one silently)."""

    def construct_mapping(self, node: yaml.MappingNode, deep: bool = False) -> dict:
        seen = set()
        for key_node, _ in node.value:
            if isinstance(key_node, yaml.ScalarNode) and key_node.tag != "tag:yaml.org,2002:merge":
                key = self.construct_object(key_node)
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        None, None, f"key {key!r} is given twice", key_node.start_mark
                    )
                seen.add(key)
        return super().construct_mapping(node, deep)


NumberLoader.yaml_implicit_resolvers = {
    first: list(resolvers) for first, resolvers in yaml.SafeLoader.yaml_implicit_resolvers.items()
}
# YAML 1.2's float (core schema) where 1.1's misses it: an exponent with no dot, or an unsigned one.
NumberLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:\.[0-9]+|[0-9]+(?:\.[0-9]*)?)[eE][-+]?[0-9]+$"),
    list("-+.0123456789"),
)


class SchemaError(ValueError):
    """A value a file may not hold: ``path`` is where it sits (``probes[2].position_m``, '' for
    the whole file) and ``problem`` what is wrong, starting ``= value`` when it names the value."""

    def __init__(self, path: str, problem: str):
        super().__init__(path, problem)
        self.path = path
        self.problem = problem

    def __str__(self) -> str:
        if not self.path:
            return self.problem.removeprefix("= ")
        return f"{self.path} {self.problem}" if self.problem.startswith("= ") else f"{self.path}: {self.problem}"


def refused(path: str, value: Any, expected: str) -> SchemaError:
    """The refusal of ``value`` at ``path``: ``path = value expected``."""
    return SchemaError(path, f"= {value!r} {expected}")


@contextlib.contextmanager
def at(key: str | int) -> Iterator[None]:
    """A ValueError inside is about the value at ``key`` (a mapping's key, or a list's index as
    an int): its key path starts there."""
    step = f"[{key}]" if isinstance(key, int) else key
    try:
        yield
    except SchemaError as error:
        inner = error.path
        path = step + inner if not inner or inner.startswith("[") else f"{step}.{inner}"
        raise SchemaError(path, error.problem) from None
    except ValueError as error:
        raise SchemaError(step, _one_line(str(error))) from None


def yaml_problem(error: yaml.YAMLError) -> str:
    """What is wrong with a YAML text, on one line, with its line and column where known."""
    if isinstance(error, yaml.MarkedYAMLError):
        mark = error.problem_mark
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark is not None else ""
        return f"not valid YAML: {where}{error.problem or error.context}"
    return f"not valid YAML: {_one_line(str(error))}"


def parse_yaml(text: str) -> Any:
    """The data of a YAML text, its numbers as YAML 1.2 reads them (:class:`NumberLoader`);
    ValueError on one line for a text that is no YAML."""
    try:
        return yaml.load(text, NumberLoader)
    except yaml.YAMLError as error:
        raise ValueError(yaml_problem(error)) from None
    except RecursionError:  # PyYAML composes nested collections recursively
        raise ValueError("its collections are nested deeper than any file of ours (thousands of levels)") from None


def unreadable(name: str, error: OSError | UnicodeDecodeError) -> str:
    """Why the file ``name`` cannot be read, in words."""
    if isinstance(error, UnicodeDecodeError):
        byte = error.object[error.start : error.start + 1]
        return f"{name} is not UTF-8 text (byte {error.start}: {byte!r}): save it as UTF-8"
    if isinstance(error, IsADirectoryError):
        return f"{name} is a directory, expected a file"
    if isinstance(error, FileNotFoundError):
        return f"{name} does not exist"
    return f"{name}: {error.strerror or _one_line(str(error))}"


def load_yaml(path: str | os.PathLike[str], what: str, build: Callable[[Any], T]) -> T:
    """``build`` of the data of the YAML file at ``path`` (a ``what``: "probe file", "scenario",
    …), the text read and parsed once. Whatever goes wrong, reading it or in ``build``, is a
    ValueError on one line that names the file (unless the message names it already)."""
    name = f"{what} {path}"
    try:
        text = read_input(path).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as error:
        raise ValueError(unreadable(name, error)) from None
    try:
        return build(parse_yaml(text))
    except (ValueError, TypeError) as error:
        message = _one_line(str(error))
        raise ValueError(message if str(path) in message else f"{name}: {message}") from None


def _one_line(text: str) -> str:
    return " ".join(text.split())


def as_points_m(points_m: ArrayLike) -> np.ndarray:
    """``points_m`` as a float array of shape (..., 3); ValueError otherwise."""
    points = np.asarray(points_m, dtype=float)
    if points.ndim == 0 or points.shape[-1] != 3:
        raise ValueError(f"points_m must have shape (..., 3), got shape {points.shape}")
    return points


def vector3(name: str, value: ArrayLike) -> np.ndarray:
    """A finite, read-only 3-vector; :class:`SchemaError` at ``name`` otherwise."""
    try:
        vector = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise refused(name, value, "must be a finite 3-vector") from None
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise refused(name, value, "must be a finite 3-vector")
    vector.setflags(write=False)
    return vector


def unit_vector3(name: str, value: ArrayLike) -> np.ndarray:
    """A read-only unit 3-vector along ``value``."""
    vector = vector3(name, value)
    norm = np.linalg.norm(vector)
    if norm == 0.0:
        raise refused(name, value, "must be a non-zero 3-vector")
    unit = vector / norm
    unit.setflags(write=False)
    return unit


def positive(name: str, value: float) -> float:
    """``value`` as a finite float > 0."""
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise refused(name, value, "must be a finite number > 0")
    return value


def is_number(value: Any) -> bool:
    """Whether ``value`` is a number of a file (an int or float, numpy's too; no bool)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def finite_number(name: str, value: Any) -> float:
    """``value`` as a float: a finite number, else :class:`SchemaError` at ``name``."""
    if not is_number(value):
        raise refused(name, value, "is not a number")
    if not np.isfinite(value):
        raise refused(name, value, "must be a finite number")
    return float(value)


def integer(name: str, value: Any) -> int:
    """``value`` as an int: an integer (not 1.5, not true), else :class:`SchemaError` at ``name``."""
    if not is_number(value) or not isinstance(value, (int, np.integer)):
        raise refused(name, value, "is not an integer")
    return int(value)


def text(name: str, value: Any) -> str:
    """``value``: a text, else :class:`SchemaError` at ``name``."""
    if not isinstance(value, str):
        raise refused(name, value, "is not a text (quote it)")
    return value


def plain(value: Any) -> Any:
    """``value`` as YAML-ready Python floats and lists."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    return float(value) if isinstance(value, (float, np.floating)) else value


def check_keys(what: str, given: dict, builder: Callable[..., Any]) -> None:
    """ValueError (about ``what``, '' for the mapping at hand) unless ``given`` holds every
    required argument of ``builder`` and no other."""
    parameters = inspect.signature(builder).parameters
    unknown = sorted(set(given) - set(parameters), key=str)
    missing = [k for k, p in parameters.items() if p.default is inspect.Parameter.empty and k not in given]
    if unknown or missing:
        problem = f"unknown keys {unknown}, missing keys {missing}; allowed keys are {list(parameters)}"
        raise ValueError(f"{what}: {problem}" if what else problem)


def typed(cls: type[T], given: Any, **convert: Callable[[Any], Any]) -> T:
    """The dataclass ``cls`` of the mapping ``given``, its keys checked (:func:`check_keys`): each
    value through ``convert[key]`` where there is one, else checked as the finite float
    (:func:`finite_number`), integer or text its field is declared as. A refusal is a
    :class:`SchemaError` at its key."""
    if not isinstance(given, dict):
        raise refused("", given, "must be a mapping")
    check_keys("", given, cls)
    declared = typing.get_type_hints(cls)
    values = {}
    for key, value in given.items():
        with at(key):
            values[key] = convert[key](value) if key in convert else _as_declared(declared[key], value)
    return cls(**values)


_DECLARED: dict[Any, Callable[[str, Any], Any]] = {float: finite_number, int: integer, str: text}


def _as_declared(declared: Any, value: Any) -> Any:
    check = _DECLARED.get(declared)
    return value if check is None else check("", value)
