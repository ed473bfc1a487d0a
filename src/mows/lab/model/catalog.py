"""The catalog: the built-in effects, with their physics, signatures and direct checks.

Each entry says what the effect is (``explanation``), its equation, its residual signature and
the independent measurement that tests it directly (``check``); docs/model_lab.md documents
them. The functions ``_name(config, rows, probe, *values)`` are the effects' edits of the
:class:`mows.lab.model.configuration.Configuration`. :func:`catalog` joins the plugins' effects
(:mod:`mows.lab.model.plugins`) to the built-in ones, :func:`resolve` finds effects by name or label.
"""

from __future__ import annotations

import itertools
import pathlib
from collections.abc import Iterable, Sequence

import numpy as np

from mows.lab.data.table import (
    CURVATURE,
    CURVATURE_SPREAD,
    NEIGHBOUR,
    NEIGHBOUR_FIELD,
    NEIGHBOUR_GRADIENT,
    NEIGHBOUR_HESSIAN,
    MeasurementTable,
    in_plane_gradient,
)
from mows.lab.model.configuration import Configuration, rotation_matrix, standard_gravity_vector
from mows.lab.model.effects import AT_PHYSICS, COMPONENTS, MECHANICS, ORIENTATION, READOUT, SOURCES, Effect, Parameter
from mows.lab.model.plugins import load_plugins
from mows.physics.probe import Probe
from mows.physics.schema import FloatOrArray

PHYSICAL_STRENGTH = (1.0,)  # a strength of 1 is the physics as predicted
# How far a strength may lie from 1 and still be the physics: the lab's model of an effect of
# known size leaves out about 1 % (a ring-down's fit starts 3 ms after the switch-off and the
# probe turns into the compliant stop: its start swing's square is ~1 % off the stop's).
STRENGTH_TOLERANCE = 0.01
# The spread of the thermoelastic coefficient of spring steels about the probe file's value, 1/K.
SPRING_TEMP_COEFF_STD_PER_K = 2e-4


def _strength_prior(probe: Probe, table: MeasurementTable) -> tuple[tuple[float, float]]:
    return ((1.0, STRENGTH_TOLERANCE),)


def _curvature_prior(probe: Probe, table: MeasurementTable) -> tuple[tuple[float, float] | None, ...]:
    """What the reference's sources make of each curvature component where a field source gives
    the reference (the table's CURVATURE columns: its value at the probe ± its change over the
    probe's placement); nothing is said where the reference is a field and gradient alone."""
    if not all(table.has(name) for name in (*CURVATURE, CURVATURE_SPREAD)):
        return (None,) * len(CURVATURE)
    spread = float(np.max(table.columns[CURVATURE_SPREAD]))
    return tuple((float(np.median(table.columns[name])), spread) for name in CURVATURE)


def _angle_offset(config: Configuration, rows: MeasurementTable, probe: Probe, offset_rad: float) -> None:
    config.theta0_rad = config.theta0_rad + offset_rad


def _plane_tilt(
    config: Configuration, rows: MeasurementTable, probe: Probe, tilt_x_rad: float, tilt_y_rad: float
) -> None:
    rotation = rotation_matrix((tilt_x_rad, tilt_y_rad, 0.0))
    config.field_t = config.field_t @ rotation.T
    config.gradient_t_per_m = rotation @ config.gradient_t_per_m @ rotation.T


def _field_offset(config: Configuration, rows: MeasurementTable, probe: Probe, bx_t: float, by_t: float) -> None:
    config.field_t = config.field_t + np.array([bx_t, by_t, 0.0])


def in_plane_hessian(hxxx: FloatOrArray, hxxy: FloatOrArray, hxyy: FloatOrArray, hyyy: FloatOrArray) -> np.ndarray:
    """The fully symmetric H[..., i, j, k] = ∂²B_i/∂x_j∂x_k with in-plane indices only
    (shape of the values + (3, 3, 3)).

    Symmetry makes each component depend only on how many of its indices are y."""
    values = np.broadcast_arrays(hxxx, hxxy, hxyy, hyyy)
    hessian = np.zeros(values[0].shape + (3, 3, 3))
    for index in itertools.product((0, 1), repeat=3):
        hessian[(...,) + index] = values[sum(index)]
    return hessian


def _field_curvature(
    config: Configuration, rows: MeasurementTable, probe: Probe, hxxx: float, hxxy: float, hxyy: float, hyyy: float
) -> None:
    hessian = in_plane_hessian(hxxx, hxxy, hxyy, hyyy)
    config.hessian_t_per_m2 = hessian[None] if config.hessian_t_per_m2 is None else config.hessian_t_per_m2 + hessian
    config.hessian_t_per_m2 = np.broadcast_to(config.hessian_t_per_m2, (len(config.theta0_rad), 3, 3, 3))


def _mutual_coupling(config: Configuration, rows: MeasurementTable, probe: Probe, moment_scale: float) -> None:
    field = np.stack([getattr(rows, name) for name in NEIGHBOUR_FIELD], -1)
    gradient = in_plane_gradient(*(getattr(rows, name) for name in NEIGHBOUR_GRADIENT))
    hessian = in_plane_hessian(*(getattr(rows, name) for name in NEIGHBOUR_HESSIAN))
    config.neighbour_field_t = moment_scale * field
    config.neighbour_gradient_t_per_m = moment_scale * gradient
    config.hessian_t_per_m2 = moment_scale * hessian + (
        0.0 if config.hessian_t_per_m2 is None else config.hessian_t_per_m2
    )


def _moment_scale(config: Configuration, rows: MeasurementTable, probe: Probe, scale_error: float) -> None:
    config.moment_factor = config.moment_factor * (1.0 + scale_error)


def _transverse_gradient(config: Configuration, rows: MeasurementTable, probe: Probe, strength: float) -> None:
    config.transverse = strength


def _static_deflection(config: Configuration, rows: MeasurementTable, probe: Probe, strength: float) -> None:
    config.deflection = strength


def _gravity(config: Configuration, rows: MeasurementTable, probe: Probe, down_x: float, down_y: float) -> None:
    config.gravity_m_per_s2 = np.broadcast_to(standard_gravity_vector(down_x, down_y), config.field_t.shape)


def _thermal_drift(config: Configuration, rows: MeasurementTable, probe: Probe, spring_temp_coeff_per_k: float) -> None:
    config.spring_nm_per_rad = config.spring_nm_per_rad * (
        1.0 + spring_temp_coeff_per_k * (rows.temperature_k - probe.reference_temperature_k)
    )


def _spring_drift(config: Configuration, rows: MeasurementTable, probe: Probe, rate_per_s: float) -> None:
    config.spring_nm_per_rad = config.spring_nm_per_rad * (1.0 + rate_per_s * rows.t_s)


def _finite_amplitude(config: Configuration, rows: MeasurementTable, probe: Probe, strength: float) -> None:
    config.amplitude = strength


def _housing_stop(config: Configuration, rows: MeasurementTable, probe: Probe, stop_error_rad: float) -> None:
    config.stop_rad = config.stop_rad + stop_error_rad


def _damping_shift(config: Configuration, rows: MeasurementTable, probe: Probe, strength: float) -> None:
    config.damping = strength
    if rows.has("damping_per_s"):
        config.damping_per_s = rows.damping_per_s


def _strength(description: str, bound: float = 5.0) -> tuple[Parameter, ...]:
    return (Parameter("strength", "1", -bound, bound, 1.0, description),)


def _in_plane(x: str, y: str, unit: str, bound: float, step: float, description: str) -> tuple[Parameter, ...]:
    """The parameters of an in-plane vector's x and y components; ``description`` names the
    component at ``{}``."""
    return tuple(Parameter(name, unit, -bound, bound, step, description.format(c)) for name, c in ((x, "x"), (y, "y")))


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
        _transverse_gradient,
        COMPONENTS,
        priority=30,
        physical=PHYSICAL_STRENGTH,
        prior=_strength_prior,
        check="rotate in a known anti-Helmholtz gradient G along x: the 2θ0 amplitude of Δf is "
        "(9/4)·m·l·G/kM·f00/2 with this effect, a third of that without",
    ),
    Effect(
        "field_curvature",
        "Near a source the field is not linear over the lever's arc: the second derivatives "
        "H = ∂²B/∂x² at the probe add −m·l²·∂²Bx'/∂y'² and more to the stiffness. Only the four "
        "in-plane components of the (fully symmetric) Hessian act on the lever.",
        "U(θ) ∋ −m·u(θ)·½·H:δr δr, δr = l·(cos θ − 1, sin θ); k ∋ −m·l²·H_x'y'y' + …",
        "harmonics 1 and 3 of θ0, independent of the reference field; grows near sources",
        (
            Parameter("hxxx_t_per_m2", "T/m²", -1e3, 1e3, 1.0, "∂²Bx/∂x²"),
            Parameter("hxxy_t_per_m2", "T/m²", -1e3, 1e3, 1.0, "∂²Bx/∂x∂y"),
            Parameter("hxyy_t_per_m2", "T/m²", -1e3, 1e3, 1.0, "∂²Bx/∂y²"),
            Parameter("hyyy_t_per_m2", "T/m²", -1e3, 1e3, 1.0, "∂²By/∂y²"),
        ),
        _field_curvature,
        SOURCES,
        priority=50,
        check="map the field at two more points (±5 mm) with the reference: the curvature is their second difference",
        prior=_curvature_prior,
    ),
    Effect(
        "static_deflection",
        "A field across the probe axis, By', turns the lever to a new rest angle θs ≈ m·By'/k, "
        "where the field spring is stiffer: k grows by ≈ (m·By')²/kM (7 mHz at 170 µT). The "
        "size follows from m, kM and the reference field; strength 1 is that prediction.",
        "k = U''(θs), U'(θs) = 0; k ≈ kM + m·Bx' + (m·By')²/kM, blended by the strength λ",
        "harmonics 0 and 2 of θ0, growing as |B|² (B⊥²); absent in a field along x'",
        _strength("blend between Eq. 6 (0) and the exact rest angle (1)"),
        _static_deflection,
        COMPONENTS,
        priority=10,
        physical=PHYSICAL_STRENGTH,
        prior=_strength_prior,
        check="repeat the sweep at twice the field: this effect grows 4×, field terms 2×",
    ),
    Effect(
        "finite_amplitude",
        "−m·B·cos θ is not a linear spring: at amplitude A the first-harmonic stiffness of the "
        "field term is m·Bx'·2·J1(A)/A (0.991 at 15°, 0.978 at 24°), and the frequency drifts "
        "as the ring-down decays. The fit reports an average over the ring-down (weights of "
        "mows.physics.ringdown_average) from the start swing: the housing stop less the deflection "
        "|θs| (an external table's amplitude_deg where it gives one).",
        "k(A) = (1/πA)·∫U'(θc + A·cos φ)·cos φ dφ;  f = f(0) + s·(Σ c_q·f(A_q) − f(0))",
        "harmonic 1 of θ0 (∝ Bx'·A²), scales with the excitation amplitude squared and with |B|",
        _strength("blend between the small-amplitude (0) and the ring-down-averaged frequency (1)"),
        _finite_amplitude,
        READOUT,
        priority=20,
        physical=PHYSICAL_STRENGTH,
        prior=_strength_prior,
        check="repeat at half the excitation amplitude: this effect falls 4×",
    ),
    Effect(
        "housing_stop",
        "Every ring-down starts at the housing stop, so its swing about the rest angle is the stop "
        "less the deflection, A0 = θstop − |θs|; the finite amplitude is read from there. The "
        "probe's theta_stop_rad is the stop as calibrated; this moves it, one angle for the table.",
        "A0 = θstop + δ − |θs|, θs the exact rest angle in the row's field",
        "only through the finite amplitude: ∝ Bx'·A0·δ, harmonic 1 of θ0",
        (Parameter("stop_error_rad", "rad", -0.2, 0.2, 1e-3, "δ, added to the probe's theta_stop_rad"),),
        _housing_stop,
        READOUT,
        priority=22,
        prior=lambda probe, table: ((0.0, probe.theta_stop_std_rad),),
        check="film the lever at the stop (or fit θmax of ring-downs in zero field, where θs = 0)",
    ),
    Effect(
        "gravity",
        "When the rotation plane is not level the magnet is a pendulum: gravity pulls the mass "
        "a at the end of the lever, adding a·g·l·(d·x') to the stiffness, where d is the unit "
        "downward vector's in-plane part. It acts like an in-plane field a·g·l/m ≈ 154 µT·|d| "
        "along d, independent of any current. The size a·g·l is known; d is free.",
        "U(θ) ∋ −a·l·g·(d·u(θ)); k ∋ a·g·l·(d_x·cos θ0 + d_y·sin θ0)",
        "harmonic 1 of θ0 with fixed phase, independent of |B|, current and time",
        _in_plane("down_x", "down_y", "1", 1.0, 1e-2, "in-plane {} component of the unit downward vector"),
        _gravity,
        MECHANICS,
        priority=15,
        check="level the rotation plane with an inclinometer (or tilt it by a known angle): "
        "only gravity's share changes",
    ),
    Effect(
        "thermal_drift",
        "The spring steel softens as it warms: kM(T) = kM·(1 + α·(T − T_ref)) with α ≈ −2.6e-4/K "
        "(≈ −15 mHz/K at 112 Hz). The residual follows the temperature, not the angle.",
        "kM → kM·(1 + α·(T − T_ref)), α free (1/K)",
        "no angle dependence; follows temperature_k (and so time)",
        (Parameter("spring_temp_coeff_per_k", "1/K", -1e-2, 1e-2, 1e-5, "relative change of kM per kelvin"),),
        _thermal_drift,
        MECHANICS,
        requires=("temperature_k",),
        priority=40,
        prior=lambda probe, table: ((probe.spring_temp_coeff_per_k, SPRING_TEMP_COEFF_STD_PER_K),),
        check="change the temperature by a few kelvin at a fixed angle",
    ),
    Effect(
        "spring_drift",
        "The spring changes slowly with wear or creep: kM(t) = kM·(1 + r·t). Without a "
        "temperature record this is also what thermal drift looks like.",
        "kM → kM·(1 + r·t), r free (1/s)",
        "no angle dependence; linear in time t_s",
        (Parameter("rate_per_s", "1/s", -1e-3, 1e-3, 1e-8, "relative change of kM per second"),),
        _spring_drift,
        MECHANICS,
        requires=("t_s",),
        priority=90,
        generic=True,
        check="repeat a fixed-angle reference point at the start and end of each sweep",
    ),
    Effect(
        "angle_offset",
        "The probe axis is not where the stage says: θ0,true = θ0 + δθ (mounting or encoder "
        "zero). The model's field and gradient patterns turn with it.",
        "x' = (cos(θ0 + δθ), sin(θ0 + δθ))",
        "harmonic 1 in quadrature with the field (∝ B⊥ = By') and harmonic 2 ∝ G; scales with |B|",
        (Parameter("offset_rad", "rad", -0.5, 0.5, 1e-3, "δθ, added to θ0"),),
        _angle_offset,
        ORIENTATION,
        priority=60,
        generic=True,
        check="sweep in a strong known uniform field: the phase of the 1θ0 harmonic is δθ",
    ),
    Effect(
        "damping_shift",
        "The ring-down frequency is the damped one, ω = √(k/J − δ²) (Eq. S1), and δ can change "
        "with the field (eddy currents, magnetic friction). Eq. 6 scales f00 as if δ were zero "
        "and fixed; this uses the damping fitted per row (column damping_per_s) when present.",
        "f = f00·√((k/J − δ_row²)/(kM/J − δ0²)) (blended by the strength)",
        "follows damping_per_s; otherwise ∝ δ0²·(k − kM) (tiny, only at mT fields)",
        _strength("blend between Eq. 6 (0) and the damped form of Eq. S1 (1)", bound=100.0),
        _damping_shift,
        READOUT,
        priority=25,
        physical=PHYSICAL_STRENGTH,
        prior=_strength_prior,
        check="compare ring-downs of equal frequency but different damping",
    ),
    Effect(
        "field_offset",
        "A uniform in-plane field the reference does not see: an offset or gain error of the "
        "reference magnetometer, or a source near the probe but far from the reference. In "
        "rotation data it is indistinguishable from gravity (both act as −vector·u(θ)).",
        "B → B_ref + (b_x, b_y, 0)",
        "harmonic 1 of θ0 with fixed phase, independent of the reference",
        _in_plane("bx_t", "by_t", "T", 1e-3, 1e-6, "unreferenced field, {}"),
        _field_offset,
        SOURCES,
        priority=70,
        generic=True,
        check="check the reference magnetometer's zero (turn it by 180° in a fixed field)",
    ),
    Effect(
        "plane_tilt",
        "The rotation plane is tilted against the reference's frame by small rotations about x "
        "and y, so that part of the reference's Bz lies in the plane of the swing.",
        "B_plane = R(t_x, t_y)·B_ref, G_plane = R·G·Rᵀ",
        "harmonic 1 of θ0 proportional to the reference's Bz",
        _in_plane("tilt_x_rad", "tilt_y_rad", "rad", 0.5, 1e-3, "rotation about {}"),
        _plane_tilt,
        ORIENTATION,
        requires=("ref_bz_t",),
        priority=80,
        check="reverse Bz alone (a z coil): this effect changes sign, the others do not",
    ),
    Effect(
        "moment_scale",
        "The calibration constant β0 = f00·m/(2kM) is off: the magnetic springs are all scaled "
        "by (1 + ε), for example m/kM from a calibration at another amplitude or temperature.",
        "k = kM + (1 + ε)·(m·Bx' + m·l·Gx'x' + …)",
        "proportional to the base model's own shift (harmonics 1 and 2), grows with |B| and G",
        (Parameter("scale_error", "1", -0.5, 0.5, 1e-3, "ε, relative error of m/kM"),),
        _moment_scale,
        COMPONENTS,
        priority=85,
        generic=True,
        prior=lambda probe, table: ((0.0, probe.beta0_rel_std),),
        check="a field sweep along x' at one amplitude: the slope at B = 0 is β0",
    ),
    Effect(
        "mutual_coupling",
        "Probes that share a scene feel each other's magnets: each neighbour is a dipole whose "
        "moment turns with its own orientation, 1.4 µT at 5 cm on the axis of the paper's "
        "moment, about 5 mHz, fifteen times a probe's precision. The neighbours' exact dipole "
        "field, gradient and Hessian at each magnet, from their orientations in the same sweep "
        "step, join the reference field in the full potential; the strength scales the "
        "neighbours' moments (1 = their probe files' moments).",
        "B → B_ref + s·Σ_j B_dipole,j(r), G and H likewise (Eq. S8 before its far-field reduction)",
        "harmonics 0 and 2 of θ0 with a phase that differs from probe to probe (their bearings), "
        "harmonics 1 and 3 through the lever; absent on a one-probe table",
        (Parameter("moment_scale", "1", -5.0, 5.0, 1.0, "s, the neighbours' moments over their probe files'"),),
        _mutual_coupling,
        SOURCES,
        requires=NEIGHBOUR,
        priority=35,
        physical=PHYSICAL_STRENGTH,
        prior=lambda probe, table: ((1.0, probe.beta0_rel_std),),
        needs="needs two or more probes in one table, with their sweep steps and magnet positions "
        "(columns probe, step, magnet_x_m, magnet_y_m, magnet_z_m): a single probe has no neighbour",
        check="take one probe out of the scene: its neighbours' shifts vanish, or turn it by 180° at a "
        "fixed stage angle: they change sign",
    ),
)


def catalog(plugins: Iterable[str | pathlib.Path] = ()) -> dict[str, Effect]:
    """Name → :class:`Effect` for the built-in effects and the effects of ``plugins``
    (file paths or entry-point names, see :func:`load_plugins`)."""
    effects = {e.name: e for e in CATALOG}
    for extra in load_plugins(plugins):
        if extra.name in effects:
            raise ValueError(f"plugin effect '{extra.name}' has the name of an effect already loaded")
        effects[extra.name] = extra
    return effects


def resolve(names: Sequence[str], effects: dict[str, Effect]) -> list[Effect]:
    """The effects called ``names`` (a name, or its label ``name (at physics)`` for the effect
    held at its physical values); ValueError naming the unknown ones."""
    bare = [name.removesuffix(AT_PHYSICS) for name in names]
    unknown = [name for name, plain in zip(names, bare) if plain not in effects]
    if unknown:
        raise ValueError(
            f"unknown effect{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}; known: {', '.join(effects)}"
        )
    return [
        effects[plain].at_physics() if name.endswith(AT_PHYSICS) else effects[plain] for name, plain in zip(names, bare)
    ]
