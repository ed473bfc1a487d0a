"""Physical effects the published model leaves out: the catalog, user plugins, the Effect type.

Every effect edits the per-row :class:`mows.lab.physics.Configuration` (field, gradient,
Hessian, gravity, spring, readout), and the frequency follows from the potential U(θ) of
PHYSICS.md §4 with the exact rest angle and first-harmonic balance, so effects compose and stay
right at mT fields. Every effect is *off* when all its parameters are 0 and is smooth there
(score tests and refits start from 0). Where the size of an effect follows from probe
constants (gravity: a·g·l; static deflection: m, kM and By'), the free parameter is the unknown
geometry or a dimensionless strength with 1 = the physics as predicted; an effect whose size is
known entirely (``physical``) can also be held at it, with no free parameter
(:meth:`Effect.at_physics`, labelled ``name (at physics)``).

The catalog (:func:`catalog`) is documented with equations and residual signatures in
docs/model_lab.md. Plugins are Python files or entry points (group ``mows.lab.effects``) that
define effects with the :func:`effect` decorator::

    from mows.lab import effect

    @effect(name="coil_heating", parameters={"k_per_a2_nm_per_rad": (0.0, -1e-5, 1e-5, "N·m/rad/A²")},
            explanation="...", signature="grows with coil current squared")
    def coil_heating(rows, k_per_a2_nm_per_rad):
        return {"stiffness_nm_per_rad": k_per_a2_nm_per_rad * rows.coil_current_a ** 2}

A plugin returns ``stiffness_nm_per_rad`` (added to kM: it enters U as ½·Δk·θ², so it goes
through the same equilibrium and harmonic balance) and/or ``frequency_hz`` (added to f).
"""
from __future__ import annotations

import dataclasses
import importlib.metadata
import importlib.util
import inspect
import itertools
import pathlib
import weakref
from typing import Callable

import numpy as np

from mows.physics import ringdown_average
from mows.lab.physics import Configuration, rotation_matrix, standard_gravity_vector
from mows.lab.table import MissingColumnError

ENTRY_POINT_GROUP = "mows.lab.effects"
AT_PHYSICS = " (at physics)"  # label suffix of an effect held at its physical values
PHYSICAL_STRENGTH = (1.0,)    # a strength of 1 is the physics as predicted

# Stages: effects are applied in this order, so that e.g. an angle offset turns the probe
# before fields are projected, and the readout comes last.
ORIENTATION, SOURCES, COMPONENTS, MECHANICS, READOUT = range(5)


@dataclasses.dataclass(frozen=True)
class Parameter:
    """A free parameter: value 0 is "effect off"; ``lower``/``upper`` are physical bounds;
    ``scale`` a typical size (finite-difference step and parameter scaling)."""

    name: str
    unit: str
    lower: float
    upper: float
    scale: float
    description: str = ""

    def __post_init__(self):
        if not (self.lower <= 0.0 <= self.upper and self.lower < self.upper and self.scale > 0):
            raise ValueError(f"parameter {self.name}: needs lower ≤ 0 ≤ upper, lower < upper and scale > 0 "
                             f"(got {self.lower}, {self.upper}, {self.scale})")


@dataclasses.dataclass(frozen=True, eq=False)
class Effect:
    """One physical effect.

    ``apply(config, rows, probe, *values)`` edits the configuration in place (values in the
    order of ``parameters``). ``requires`` names table columns without which the effect cannot
    be tested. ``priority`` breaks ties inside a group of effects the data cannot tell apart
    (smaller first; docs/model_lab.md). ``check`` names an independent measurement that tests
    the effect directly. ``physical`` holds the parameter values at which the effect is the
    physics as predicted from the probe constants and the table (None when its size is not
    known, e.g. gravity's tilt): the effect can then also be tested *at physics*, with no free
    parameter (:meth:`at_physics`).
    """

    name: str
    explanation: str
    equation: str
    signature: str
    parameters: tuple
    apply: Callable
    stage: int = MECHANICS
    requires: tuple = ()
    priority: int = 100
    check: str = ""
    origin: str = "catalog"
    physical: tuple | None = None
    free: "Effect | None" = None   # of an effect held at physics: the same effect with its parameters free

    @property
    def parameter_names(self) -> tuple:
        return tuple(p.name for p in self.parameters)

    @property
    def fixed(self) -> bool:
        """True for an effect held at its physical values (no free parameter)."""
        return self.free is not None

    @property
    def label(self) -> str:
        """The name, with the form when the effect is held at physics."""
        return f"{self.name}{AT_PHYSICS}" if self.fixed else self.name

    def at_physics(self) -> "Effect":
        """This effect held at its ``physical`` values: same name, no free parameter."""
        if self.fixed:
            return self
        if self.physical is None:
            raise ValueError(f"effect {self.name} has no physical value: its size is not known in advance")
        apply, values = self.apply, self.physical
        return dataclasses.replace(self, parameters=(), free=self,
                                   apply=lambda config, rows, probe: apply(config, rows, probe, *values))

    def missing_columns(self, table) -> tuple:
        return tuple(name for name in self.requires if not table.has(name))

    def __add__(self, other):
        from mows.lab.model import FrequencyModel

        return FrequencyModel.combine(self, other)

    __radd__ = __add__

    def __repr__(self):
        return f"Effect({self.name!r}, parameters={list(self.parameter_names)})"


# --- the catalog ----------------------------------------------------------------------------
def _angle_offset(config, rows, probe, offset_rad):
    config.theta0_rad = config.theta0_rad + offset_rad


def _plane_tilt(config, rows, probe, tilt_x_rad, tilt_y_rad):
    rotation = rotation_matrix((tilt_x_rad, tilt_y_rad, 0.0))
    config.field_t = config.field_t @ rotation.T
    config.gradient_t_per_m = rotation @ config.gradient_t_per_m @ rotation.T


def _field_offset(config, rows, probe, bx_t, by_t):
    config.field_t = config.field_t + np.array([bx_t, by_t, 0.0])


def in_plane_hessian(hxxx, hxxy, hxyy, hyyy) -> np.ndarray:
    """The fully symmetric H[i, j, k] = ∂²B_i/∂x_j∂x_k with in-plane indices only (3, 3, 3).

    Symmetry makes each component depend only on how many of its indices are y."""
    values = (hxxx, hxxy, hxyy, hyyy)
    hessian = np.zeros((3, 3, 3))
    for index in itertools.product((0, 1), repeat=3):
        hessian[index] = values[sum(index)]
    return hessian


def _field_curvature(config, rows, probe, hxxx, hxxy, hxyy, hyyy):
    hessian = in_plane_hessian(hxxx, hxxy, hxyy, hyyy)
    config.hessian_t_per_m2 = hessian[None] if config.hessian_t_per_m2 is None else config.hessian_t_per_m2 + hessian
    config.hessian_t_per_m2 = np.broadcast_to(config.hessian_t_per_m2, (len(config.theta0_rad), 3, 3, 3))


def _moment_scale(config, rows, probe, scale_error):
    config.moment_factor = config.moment_factor * (1.0 + scale_error)


def _transverse_gradient(config, rows, probe, strength):
    config.transverse = strength


def _static_deflection(config, rows, probe, strength):
    config.deflection = strength


def _gravity(config, rows, probe, down_x, down_y):
    config.gravity_m_per_s2 = np.broadcast_to(standard_gravity_vector(down_x, down_y), config.field_t.shape)


def _thermal_drift(config, rows, probe, spring_temp_coeff_per_k):
    config.spring_nm_per_rad = config.spring_nm_per_rad * (
        1.0 + spring_temp_coeff_per_k * (rows.temperature_k - probe.reference_temperature_k))


def _spring_drift(config, rows, probe, rate_per_s):
    config.spring_nm_per_rad = config.spring_nm_per_rad * (1.0 + rate_per_s * rows.t_s)


def _finite_amplitude(config, rows, probe, strength):
    config.amplitude = strength


def _damping_shift(config, rows, probe, strength):
    config.damping = strength
    if rows.has("damping_per_s"):
        config.damping_per_s = rows.damping_per_s


def _strength(description, bound=5.0):
    return (Parameter("strength", "1", -bound, bound, 1.0, description),)


CATALOG = (
    Effect(
        "transverse_gradient",
        "Any real gradient obeys ∇·B = 0 and ∇×B = 0, so Gx'x' never comes alone. The magnet "
        "swings on an arc, and along it the field also changes across the lever: the stiffness "
        "gains −2·m·l·Gy'y', and Gx'y' turns the rest angle. For an anti-Helmholtz pair along x "
        "(Gyy = −Gxx/2) this doubles the gradient response at θ0 = 0.",
        "k = kM + m·Bx' + m·l·(Gx'x' − 2·s·Gy'y') + …, s = strength (1 = measured gradient)",
        "harmonics 0 and 2 of θ0, proportional to the gradient G; absent without gradient",
        _strength("weight of the gradient components other than Gx'x' (1 = Maxwell, as measured)"),
        _transverse_gradient, COMPONENTS, priority=30, physical=PHYSICAL_STRENGTH,
        check="rotate a known anti-Helmholtz gradient: the 2θ0 amplitude is 2·m·l·G/kM·f00/2 with, "
              "0.5× that without"),
    Effect(
        "field_curvature",
        "Near a source the field is not linear over the lever's arc: the second derivatives "
        "H = ∂²B/∂x² at the probe add −m·l²·∂²Bx'/∂y'² and more to the stiffness. Only the four "
        "in-plane components of the (fully symmetric) Hessian act on the lever.",
        "U(θ) ∋ −m·u(θ)·½·H:δr δr, δr = l·(cos θ − 1, sin θ); k ∋ −m·l²·H_x'y'y' + …",
        "harmonics 1 and 3 of θ0, independent of the reference field; grows near sources",
        (Parameter("hxxx_t_per_m2", "T/m²", -1e3, 1e3, 1.0, "∂²Bx/∂x²"),
         Parameter("hxxy_t_per_m2", "T/m²", -1e3, 1e3, 1.0, "∂²Bx/∂x∂y"),
         Parameter("hxyy_t_per_m2", "T/m²", -1e3, 1e3, 1.0, "∂²Bx/∂y²"),
         Parameter("hyyy_t_per_m2", "T/m²", -1e3, 1e3, 1.0, "∂²By/∂y²")),
        _field_curvature, SOURCES, priority=50,
        check="map the field at two more points (±5 mm) with the reference: the curvature is their "
              "second difference"),
    Effect(
        "static_deflection",
        "A field across the probe axis, By', turns the lever to a new rest angle θs ≈ m·By'/k, "
        "where the field spring is stiffer: k grows by ≈ (m·By')²/kM (7 mHz at 170 µT). The "
        "size follows from m, kM and the reference field; strength 1 is that prediction.",
        "k = U''(θs), U'(θs) = 0; k ≈ kM + m·Bx' + (m·By')²/kM, blended by the strength λ",
        "harmonics 0 and 2 of θ0, growing as |B|² (B⊥²); absent in a field along x'",
        _strength("blend between Eq. 6 (0) and the exact rest angle (1)"),
        _static_deflection, COMPONENTS, priority=10, physical=PHYSICAL_STRENGTH,
        check="repeat the sweep at twice the field: this effect grows 4×, field terms 2×"),
    Effect(
        "finite_amplitude",
        "−m·B·cos θ is not a linear spring: at amplitude A the first-harmonic stiffness of the "
        "field term is m·Bx'·2·J1(A)/A (0.991 at 15°, 0.978 at 24°), and the frequency drifts "
        "as the ring-down decays. The fit reports an average over the ring-down (weights of "
        "mows.physics.ringdown_average) from the start amplitude (column amplitude_deg, else the "
        "housing stop).",
        "k(A) = (1/πA)·∫U'(θc + A·cos φ)·cos φ dφ;  f = f(0) + s·(Σ c_q·f(A_q) − f(0))",
        "harmonic 1 of θ0 (∝ Bx'·A²), scales with the excitation amplitude squared and with |B|",
        _strength("blend between the small-amplitude (0) and the ring-down-averaged frequency (1)"),
        _finite_amplitude, READOUT, priority=20, physical=PHYSICAL_STRENGTH,
        check="repeat at half the excitation amplitude: this effect falls 4×"),
    Effect(
        "gravity",
        "When the rotation plane is not level the magnet is a pendulum: gravity pulls the mass "
        "a at the end of the lever, adding a·g·l·(d·x') to the stiffness, where d is the unit "
        "downward vector's in-plane part. It acts like an in-plane field a·g·l/m ≈ 154 µT·|d| "
        "along d, independent of any current. The size a·g·l is known; d is free.",
        "U(θ) ∋ −a·l·g·(d·u(θ)); k ∋ a·g·l·(d_x·cos θ0 + d_y·sin θ0)",
        "harmonic 1 of θ0 with fixed phase, independent of |B|, current and time",
        (Parameter("down_x", "1", -1.0, 1.0, 1e-2, "in-plane x component of the unit downward vector"),
         Parameter("down_y", "1", -1.0, 1.0, 1e-2, "in-plane y component of the unit downward vector")),
        _gravity, MECHANICS, priority=15,
        check="level the rotation plane with an inclinometer (or tilt it by a known angle): "
              "only gravity's share changes"),
    Effect(
        "thermal_drift",
        "The spring steel softens as it warms: kM(T) = kM·(1 + α·(T − T_ref)) with α ≈ −2.6e-4/K "
        "(≈ −15 mHz/K at 112 Hz). The residual follows the temperature, not the angle.",
        "kM → kM·(1 + α·(T − T_ref)), α free (1/K)",
        "no angle dependence; follows temperature_k (and so time)",
        (Parameter("spring_temp_coeff_per_k", "1/K", -1e-2, 1e-2, 1e-5, "relative change of kM per kelvin"),),
        _thermal_drift, MECHANICS, requires=("temperature_k",), priority=40,
        check="change the temperature by a few kelvin at a fixed angle"),
    Effect(
        "spring_drift",
        "The spring changes slowly with wear or creep: kM(t) = kM·(1 + r·t). Without a "
        "temperature record this is also what thermal drift looks like.",
        "kM → kM·(1 + r·t), r free (1/s)",
        "no angle dependence; linear in time t_s",
        (Parameter("rate_per_s", "1/s", -1e-3, 1e-3, 1e-8, "relative change of kM per second"),),
        _spring_drift, MECHANICS, requires=("t_s",), priority=90,
        check="repeat a fixed-angle reference point at the start and end of each sweep"),
    Effect(
        "angle_offset",
        "The probe axis is not where the stage says: θ0,true = θ0 + δθ (mounting or encoder "
        "zero). The model's field and gradient patterns turn with it.",
        "x' = (cos(θ0 + δθ), sin(θ0 + δθ))",
        "harmonic 1 in quadrature with the field (∝ B⊥ = By') and harmonic 2 ∝ G; scales with |B|",
        (Parameter("offset_rad", "rad", -0.5, 0.5, 1e-3, "δθ, added to θ0"),),
        _angle_offset, ORIENTATION, priority=60,
        check="sweep in a strong known uniform field: the phase of the 1θ0 harmonic is δθ"),
    Effect(
        "damping_shift",
        "The ring-down frequency is the damped one, ω = √(k/J − δ²) (Eq. S1), and δ can change "
        "with the field (eddy currents, magnetic friction). Eq. 6 scales f00 as if δ were zero "
        "and fixed; this uses the damping fitted per row (column damping_per_s) when present.",
        "f = f00·√((k/J − δ_row²)/(kM/J − δ0²)) (blended by the strength)",
        "follows damping_per_s; otherwise ∝ δ0²·(k − kM) (tiny, only at mT fields)",
        _strength("blend between Eq. 6 (0) and the damped form of Eq. S1 (1)", bound=100.0),
        _damping_shift, READOUT, priority=25, physical=PHYSICAL_STRENGTH,
        check="compare ring-downs of equal frequency but different damping"),
    Effect(
        "field_offset",
        "A uniform in-plane field the reference does not see: an offset or gain error of the "
        "reference magnetometer, or a source near the probe but far from the reference. In "
        "rotation data it is indistinguishable from gravity (both act as −vector·u(θ)).",
        "B → B_ref + (b_x, b_y, 0)",
        "harmonic 1 of θ0 with fixed phase, independent of the reference",
        (Parameter("bx_t", "T", -1e-3, 1e-3, 1e-6, "unreferenced field, x"),
         Parameter("by_t", "T", -1e-3, 1e-3, 1e-6, "unreferenced field, y")),
        _field_offset, SOURCES, priority=70,
        check="check the reference magnetometer's zero (turn it by 180° in a fixed field)"),
    Effect(
        "plane_tilt",
        "The rotation plane is tilted against the reference's frame by small rotations about x "
        "and y, so that part of the reference's Bz lies in the plane of the swing.",
        "B_plane = R(t_x, t_y)·B_ref, G_plane = R·G·Rᵀ",
        "harmonic 1 of θ0 proportional to the reference's Bz",
        (Parameter("tilt_x_rad", "rad", -0.5, 0.5, 1e-3, "rotation about x"),
         Parameter("tilt_y_rad", "rad", -0.5, 0.5, 1e-3, "rotation about y")),
        _plane_tilt, ORIENTATION, requires=("ref_bz_t",), priority=80,
        check="reverse Bz alone (a z coil): this effect changes sign, the others do not"),
    Effect(
        "moment_scale",
        "The calibration constant β0 = f00·m/(2kM) is off: the magnetic springs are all scaled "
        "by (1 + ε), for example m/kM from a calibration at another amplitude or temperature.",
        "k = kM + (1 + ε)·(m·Bx' + m·l·Gx'x' + …)",
        "proportional to the base model's own shift (harmonics 1 and 2), grows with |B| and G",
        (Parameter("scale_error", "1", -0.5, 0.5, 1e-3, "ε, relative error of m/kM"),),
        _moment_scale, COMPONENTS, priority=85,
        check="a field sweep along x' at one amplitude: the slope at B = 0 is β0"),
)


def catalog(plugins=()) -> dict:
    """Name → :class:`Effect` for the built-in effects and the effects of ``plugins``
    (file paths or entry-point names, see :func:`load_plugins`)."""
    effects = {e.name: e for e in CATALOG}
    for extra in load_plugins(plugins):
        if extra.name in effects:
            raise ValueError(f"plugin effect '{extra.name}' has the name of an effect already loaded")
        effects[extra.name] = extra
    return effects


def resolve(names, effects: dict) -> list:
    """The effects called ``names`` (a name, or its label ``name (at physics)`` for the effect
    held at its physical values); ValueError naming the unknown ones."""
    bare = [name.removesuffix(AT_PHYSICS) for name in names]
    unknown = [name for name, plain in zip(names, bare) if plain not in effects]
    if unknown:
        raise ValueError(f"unknown effect{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; "
                         f"known: {', '.join(effects)}")
    return [effects[plain].at_physics() if name.endswith(AT_PHYSICS) else effects[plain]
            for name, plain in zip(names, bare)]


# --- ring-down amplitude nodes, cached per table ---------------------------------------------
_NODES = weakref.WeakKeyDictionary()


def ringdown_nodes(table, config: Configuration):
    """Amplitude nodes of the table's ring-downs, cached per table and ring-down inputs (the
    inputs also come from the probe where the table has no column: Configuration.base)."""
    inputs = (config.amplitude_start_rad, config.ringdown_damping_per_s, config.ringdown_duration_s)
    key = b"".join(np.ascontiguousarray(values, float).tobytes() for values in inputs)
    cached = _NODES.setdefault(table, {})
    if key not in cached:
        cached[key] = ringdown_average.amplitude_nodes(table.theta0_rad, *inputs)
    return cached[key]


# --- plugins --------------------------------------------------------------------------------
def effect(name: str, parameters: dict, explanation: str = "", signature: str = "", equation: str = "",
           check: str = "") -> Callable:
    """Decorator turning ``function(rows, **parameters) -> dict`` into an :class:`Effect`.

    ``parameters`` maps each name to ``(off_value, lower, upper, unit)``; the off value must
    be 0 (the effect is absent at 0) and lie within the bounds. The function receives the
    table (columns as attributes) and the parameter values, and returns a dict with
    ``stiffness_nm_per_rad`` and/or ``frequency_hz`` (scalars or per-row arrays).
    """
    specs = []
    for pname, spec in parameters.items():
        try:
            off, lower, upper, unit = spec
        except (TypeError, ValueError):
            raise ValueError(f"effect {name}: parameter {pname} needs (off_value, lower, upper, unit)") from None
        if off != 0:
            raise ValueError(f"effect {name}: parameter {pname} must be off at 0 (got off value {off})")
        specs.append(Parameter(pname, unit, float(lower), float(upper), (float(upper) - float(lower)) * 1e-3))

    def decorate(function):
        accepted = list(inspect.signature(function).parameters)[1:]
        if accepted != [p.name for p in specs]:
            raise ValueError(f"effect {name}: the function takes {accepted}, the parameters are "
                             f"{[p.name for p in specs]}")

        def apply(config, rows, probe, *values):
            result = function(rows, *values)
            unknown = set(result) - {"stiffness_nm_per_rad", "frequency_hz"}
            if unknown:
                raise ValueError(f"effect {name} returned {sorted(unknown)}; allowed: stiffness_nm_per_rad, "
                                 "frequency_hz")
            n = len(config.theta0_rad)
            config.spring_nm_per_rad = config.spring_nm_per_rad + np.broadcast_to(
                result.get("stiffness_nm_per_rad", 0.0), (n,))
            config.frequency_hz = config.frequency_hz + np.broadcast_to(result.get("frequency_hz", 0.0), (n,))

        return Effect(name, explanation or function.__doc__ or name, equation, signature, tuple(specs), apply,
                      MECHANICS, requires=(), priority=200, check=check, origin=function.__module__)
    return decorate


def load_plugins(sources) -> list:
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
            raise ValueError(f"plugin '{source}' is neither a .py file nor an entry point in group "
                             f"{ENTRY_POINT_GROUP}")
        loaded = points[0].load()
        found.extend([loaded] if isinstance(loaded, Effect) else _effects_in(vars(loaded), source))
    return found


def _effects_in_file(path: pathlib.Path) -> list:
    if not path.is_file():
        raise ValueError(f"plugin file {path} does not exist")
    spec = importlib.util.spec_from_file_location(f"mows_lab_plugin_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as error:  # a broken plugin is the user's error: say where
        raise ValueError(f"plugin file {path} failed to load: {type(error).__name__}: {error}") from error
    return _effects_in(vars(module), path)


def _effects_in(namespace: dict, source) -> list:
    effects = [value for value in namespace.values() if isinstance(value, Effect)]
    if not effects:
        raise ValueError(f"plugin {source} defines no effect (use the @mows.lab.effect decorator)")
    return effects


def testable(effect_: Effect, table, probe) -> str | None:
    """None when the effect can be evaluated on ``table``, else the reason in words."""
    missing = effect_.missing_columns(table)
    if missing:
        return f"needs column{'s' if len(missing) > 1 else ''} {', '.join(missing)}"
    try:
        effect_.apply(Configuration.base(table, probe), table, probe, *[0.0] * len(effect_.parameters))
    except MissingColumnError as error:
        return f"needs column {error.column}"
    return None
