"""Static magnetic field sources in free space, consistent with Maxwell's equations.

Every source gives the field B (tesla), its gradient G[i, j] = ∂B_i/∂x_j (T/m) and its
Hessian H[i, j, k] = ∂²B_i/∂x_j∂x_k (T/m²) at points of shape (..., 3), vectorised over the
leading dimensions. Outside the sources ∇·B = 0 and ∇×B = 0, so G is symmetric and
traceless and H is symmetric in all three indices and traceless in any pair.

Sources: :class:`UniformField`, :class:`LinearGradient`, :class:`PointDipole`,
:class:`CurrentLoop` (exact, complete elliptic integrals) and what is built from loops
(:func:`helmholtz_pair`, :func:`anti_helmholtz_pair`, :func:`solenoid`). ``a + b`` superposes
sources, ``source.scaled(k)`` multiplies one by k (a coil's field per ampere times its
current). :func:`source_from_dict` and :func:`source_to_dict` give the YAML form, SI only::

    {type: uniform, field_t: [bx, by, bz]}
    {type: linear_gradient, gradient_t_per_m: [[..], [..], [..]], origin_m: [..], field_at_origin_t: [..]}
    {type: dipole, moment_am2: [..], position_m: [..]}
    {type: loop, center_m: [..], axis: [..], radius_m: r, turns: n, current_a: i}
    {type: helmholtz | anti_helmholtz, center_m, axis, radius_m, turns, current_a}
    {type: solenoid, center_m, axis, radius_m, length_m, turns, current_a, n_loops}
    {type: sum, sources: [...]}

Helmholtz pairs and solenoids are sums of loops, and :func:`source_to_dict` writes them so.
"""
from __future__ import annotations

import inspect
from collections.abc import Callable

import numpy as np
import scipy.constants
from scipy.special import ellipe, ellipkm1, hyp2f1

MU0 = scipy.constants.mu_0  # T·m/A (CODATA 2022 in scipy 1.17)
MU0_OVER_4PI = MU0 / (4.0 * np.pi)

# A gradient tensor is accepted as symmetric and traceless to this fraction of its norm.
MAXWELL_RTOL = 1e-9

# The loop is a filament: its field diverges on the wire. Closer than this fraction of the
# radius we refuse rather than return a number dominated by the singularity.
WIRE_CLEARANCE = 1e-9

# Loop derivatives: 6th-order central differences of the exact field, step proportional to
# the distance s to the wire (the field is analytic within s, so s is its length scale).
# Against Biot–Savart quadrature of the differentiated kernel (0.002 < s/R < 4) the errors
# are < 3e-11·|B|/s (gradient) and < 4e-9·|B|/s² (Hessian); tests/physics/test_field.py.
_FD_OFFSETS = np.array([-3.0, -2.0, -1.0, 1.0, 2.0, 3.0])
_FD_WEIGHTS = np.array([-1.0, 9.0, -45.0, 45.0, -9.0, 1.0]) / 60.0
GRADIENT_STEP = 5e-3  # × s
HESSIAN_STEP = 1e-2   # × s


def as_points_m(points_m) -> np.ndarray:
    """``points_m`` as a float array of shape (..., 3); ValueError otherwise."""
    points = np.asarray(points_m, dtype=float)
    if points.ndim == 0 or points.shape[-1] != 3:
        raise ValueError(f"points_m must have shape (..., 3), got shape {points.shape}")
    return points


def vector3(name: str, value) -> np.ndarray:
    """A finite, read-only 3-vector."""
    vector = np.array(value, dtype=float)
    if vector.shape != (3,) or not np.all(np.isfinite(vector)):
        raise ValueError(f"{name} must be a finite 3-vector, got {value!r}")
    vector.setflags(write=False)
    return vector


def unit_vector3(name: str, value) -> np.ndarray:
    """A read-only unit 3-vector along ``value``."""
    vector = vector3(name, value)
    norm = np.linalg.norm(vector)
    if norm == 0.0:
        raise ValueError(f"{name} must be a non-zero 3-vector, got {value!r}")
    unit = vector / norm
    unit.setflags(write=False)
    return unit


def _positive(name: str, value) -> float:
    value = float(value)
    if not (np.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return value


def _plain(value):
    """``value`` as YAML-ready Python floats and lists."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    return float(value) if isinstance(value, (float, np.floating)) else value


class FieldSource:
    """A static field source. Subclasses implement the three derivatives of order 0, 1, 2.

    Parameters whose names are in ``_linear`` scale with the field (:meth:`scaled`);
    ``_params`` gives the constructor arguments (:func:`source_to_dict`, ``repr``).
    """

    type_name = ""
    _linear: tuple[str, ...] = ()

    def field_t(self, points_m) -> np.ndarray:
        """B at ``points_m`` (..., 3), tesla, shape (..., 3)."""
        raise NotImplementedError

    def gradient_t_per_m(self, points_m) -> np.ndarray:
        """G[..., i, j] = ∂B_i/∂x_j at ``points_m``, T/m, shape (..., 3, 3)."""
        raise NotImplementedError

    def hessian_t_per_m2(self, points_m) -> np.ndarray:
        """H[..., i, j, k] = ∂²B_i/∂x_j∂x_k at ``points_m``, T/m², shape (..., 3, 3, 3)."""
        raise NotImplementedError

    def _params(self) -> dict:
        raise NotImplementedError

    def scaled(self, factor: float) -> FieldSource:
        """This source with its field multiplied by ``factor``."""
        params = self._params()
        for name in self._linear:
            params[name] = params[name] * float(factor)
        return type(self)(**params)

    def __add__(self, other):
        if not isinstance(other, FieldSource):
            return NotImplemented
        return SumSource(_terms(self) + _terms(other))

    def __radd__(self, other):
        # Lets the built-in sum() start from 0.
        if isinstance(other, (int, float)) and other == 0:
            return self
        return NotImplemented

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={_plain(v)!r}" for k, v in self._params().items())
        return f"{type(self).__name__}({args})"


def _terms(source: FieldSource) -> tuple:
    return source.sources if isinstance(source, SumSource) else (source,)


class SumSource(FieldSource):
    """Superposition of ``sources`` (an empty sum is the zero field)."""

    type_name = "sum"

    def __init__(self, sources=()):
        self.sources = tuple(sources)
        for source in self.sources:
            if not isinstance(source, FieldSource):
                raise ValueError(f"sources must be FieldSource objects, got {source!r}")

    def _total(self, method: str, points_m, rank: int) -> np.ndarray:
        points = as_points_m(points_m)
        total = np.zeros(points.shape + (3,) * rank)
        for source in self.sources:
            total = total + getattr(source, method)(points)
        return total

    def field_t(self, points_m):
        return self._total("field_t", points_m, 0)

    def gradient_t_per_m(self, points_m):
        return self._total("gradient_t_per_m", points_m, 1)

    def hessian_t_per_m2(self, points_m):
        return self._total("hessian_t_per_m2", points_m, 2)

    def _params(self):
        return {"sources": self.sources}

    def scaled(self, factor):
        return SumSource(s.scaled(factor) for s in self.sources)


class UniformField(FieldSource):
    """The same field ``field_t`` (tesla, 3-vector) everywhere."""

    type_name = "uniform"
    _linear = ("field_t",)

    def __init__(self, field_t):
        self.uniform_t = vector3("field_t", field_t)

    def field_t(self, points_m):
        return np.broadcast_to(self.uniform_t, as_points_m(points_m).shape).copy()

    def gradient_t_per_m(self, points_m):
        return np.zeros(as_points_m(points_m).shape + (3,))

    def hessian_t_per_m2(self, points_m):
        return np.zeros(as_points_m(points_m).shape + (3, 3))

    def _params(self):
        return {"field_t": self.uniform_t}


class LinearGradient(FieldSource):
    """B(x) = B0 + G·(x − x0): a constant gradient ``gradient_t_per_m`` G[i, j] = ∂B_i/∂x_j.

    G must be symmetric (∇×B = 0) and traceless (∇·B = 0) to a fraction
    :data:`MAXWELL_RTOL` of its Frobenius norm; otherwise ValueError.
    """

    type_name = "linear_gradient"
    _linear = ("gradient_t_per_m", "field_at_origin_t")

    def __init__(self, gradient_t_per_m, origin_m=(0.0, 0.0, 0.0), field_at_origin_t=(0.0, 0.0, 0.0)):
        g = np.array(gradient_t_per_m, dtype=float)
        if g.shape != (3, 3) or not np.all(np.isfinite(g)):
            raise ValueError(f"gradient_t_per_m must be a finite 3×3 matrix, got {gradient_t_per_m!r}")
        norm = np.linalg.norm(g)
        antisymmetric = np.linalg.norm(g - g.T) / 2.0
        if antisymmetric > MAXWELL_RTOL * norm:
            raise ValueError(
                f"gradient_t_per_m is not symmetric (antisymmetric part {antisymmetric:.3g} T/m, "
                f"norm {norm:.3g} T/m): ∇×B would not vanish in free space")
        if abs(np.trace(g)) > MAXWELL_RTOL * norm:
            raise ValueError(
                f"gradient_t_per_m is not traceless (trace {np.trace(g):.3g} T/m, norm {norm:.3g} T/m): "
                "∇·B would not vanish")
        g.setflags(write=False)
        self.tensor_t_per_m = g
        self.origin_m = vector3("origin_m", origin_m)
        self.field_at_origin_t = vector3("field_at_origin_t", field_at_origin_t)

    def field_t(self, points_m):
        return self.field_at_origin_t + (as_points_m(points_m) - self.origin_m) @ self.tensor_t_per_m.T

    def gradient_t_per_m(self, points_m):
        return np.broadcast_to(self.tensor_t_per_m, as_points_m(points_m).shape + (3,)).copy()

    def hessian_t_per_m2(self, points_m):
        return np.zeros(as_points_m(points_m).shape + (3, 3))

    def _params(self):
        return {"gradient_t_per_m": self.tensor_t_per_m, "origin_m": self.origin_m,
                "field_at_origin_t": self.field_at_origin_t}


def _dipole_offset(moment_am2, offset_m):
    """m, r, r², m·r for the dipole formulas, broadcast together; ValueError at r = 0."""
    r = np.asarray(offset_m, dtype=float)
    m = np.broadcast_to(np.asarray(moment_am2, dtype=float), np.broadcast_shapes(r.shape, np.shape(moment_am2)))
    r2 = np.einsum("...i,...i->...", r, r)
    if np.any(r2 == 0.0):
        raise ValueError("a field point coincides with a point dipole, where its field is undefined")
    return m, r, r2, np.einsum("...i,...i->...", m, r)


def dipole_field_t(moment_am2, offset_m) -> np.ndarray:
    """Exact field of point dipoles, B = μ0/(4π)·(3(m·r)r/r⁵ − m/r³), tesla.

    ``moment_am2`` (..., 3) in A·m², ``offset_m`` (..., 3) = field point − dipole position;
    the two broadcast, so a moving dipole sampled in time is one call (Eq. S8 before its
    far-field reduction).
    """
    m, r, r2, mr = _dipole_offset(moment_am2, offset_m)
    inv_r3 = r2 ** -1.5
    return MU0_OVER_4PI * (3.0 * (mr * inv_r3 / r2)[..., None] * r - inv_r3[..., None] * m)


def _symmetrised(t):
    """t_ijk + t_jik + t_kji over the last three axes (t symmetric in j, k)."""
    return t + np.swapaxes(t, -3, -2) + np.swapaxes(t, -3, -1)


class PointDipole(FieldSource):
    """Point dipole of moment ``moment_am2`` (A·m²) at ``position_m``; exact derivatives."""

    type_name = "dipole"
    _linear = ("moment_am2",)

    def __init__(self, moment_am2, position_m=(0.0, 0.0, 0.0)):
        self.moment_am2 = vector3("moment_am2", moment_am2)
        self.position_m = vector3("position_m", position_m)

    def field_t(self, points_m):
        return dipole_field_t(self.moment_am2, as_points_m(points_m) - self.position_m)

    def gradient_t_per_m(self, points_m):
        # G_ij = 3μ0/(4π r⁵)·[m_i r_j + m_j r_i + (m·r)δ_ij − 5(m·r) r_i r_j / r²]
        m, r, r2, mr = _dipole_offset(self.moment_am2, as_points_m(points_m) - self.position_m)
        outer = m[..., :, None] * r[..., None, :]
        bracket = (outer + np.swapaxes(outer, -1, -2) + mr[..., None, None] * np.eye(3)
                   - 5.0 * (mr / r2)[..., None, None] * r[..., :, None] * r[..., None, :])
        return 3.0 * MU0_OVER_4PI * r2[..., None, None] ** -2.5 * bracket

    def hessian_t_per_m2(self, points_m):
        # ∂_k of G_ij: 3μ0/(4π)·{Σ m_i δ_jk /r⁵ − 5 Σ [m_i r_j r_k + (m·r) r_i δ_jk] /r⁷
        #                       + 35 (m·r) r_i r_j r_k /r⁹}, Σ over the three index placements.
        m, r, r2, mr = _dipole_offset(self.moment_am2, as_points_m(points_m) - self.position_m)
        eye = np.eye(3)
        rr = r[..., :, None] * r[..., None, :]
        m_delta = _symmetrised(m[..., :, None, None] * eye)
        mixed = _symmetrised(m[..., :, None, None] * rr[..., None, :, :]
                             + mr[..., None, None, None] * r[..., :, None, None] * eye)
        rrr = r[..., :, None, None] * rr[..., None, :, :]
        inv_r2 = (1.0 / r2)[..., None, None, None]
        return (3.0 * MU0_OVER_4PI * r2[..., None, None, None] ** -2.5
                * (m_delta - 5.0 * inv_r2 * mixed + 35.0 * inv_r2**2 * mr[..., None, None, None] * rrr))

    def _params(self):
        return {"moment_am2": self.moment_am2, "position_m": self.position_m}


def _central_jacobian(func, points: np.ndarray, step_m: np.ndarray) -> np.ndarray:
    """∂func/∂x_j by a 6th-order central difference with per-point step ``step_m`` (...).

    ``func`` maps (..., 3) → (..., *out); the result has shape (..., *out, 3).
    """
    lead = points.ndim - 1
    shifts = _FD_OFFSETS[:, None, None] * np.eye(3)                       # (s, j, 3)
    stencil = points[..., None, None, :] + step_m[..., None, None, None] * shifts
    values = func(stencil)                                                # (..., s, j, *out)
    values = np.moveaxis(values, (lead, lead + 1), (-2, -1))              # (..., *out, s, j)
    derivative = np.einsum("...sj,s->...j", values, _FD_WEIGHTS)
    return derivative / step_m.reshape(step_m.shape + (1,) * (derivative.ndim - step_m.ndim))


class CurrentLoop(FieldSource):
    """Circular filament of radius ``radius_m`` about ``center_m``, normal ``axis``.

    ``turns`` × ``current_a`` ampere-turns; positive current circulates right-handedly
    about ``axis``, so the field at the centre is +μ0·N·I/(2R)·axis.

    Field: exact, with the complete elliptic integrals K(m), E(m) of parameter
    m = k² = 4Rρ/β² (Smythe; Simpson et al. 2001), α² = (R − ρ)² + z², β² = (R + ρ)² + z²::

        B_z = μ0NI / (2π α² β) · [(R² − ρ² − z²)·E + α²·K]
        B_ρ/ρ = 4μ0NI R² z / (π β⁵) · J(m),   J(m) = ∫₀^{π/2} sin⁴u (1 − m sin²u)^(−3/2) du

    J = (3π/16)·₂F₁(3/2, 5/2; 3; m) = ((2 − m)E − 2(1 − m)K) / (m²(1 − m)); the series
    form is used for m < ½ (the closed form cancels there), the closed form with
    K = ellipkm1(α²/β²) for m ≥ ½ (accurate up to the wire). B = (B_ρ/ρ)·ρ_vec + B_z·axis
    needs no division by ρ, so the axis is an ordinary point.

    Gradient and Hessian: 6th-order central differences of this field, with steps
    :data:`GRADIENT_STEP` and :data:`HESSIAN_STEP` times the distance s to the wire
    (accuracy in the module header). Points within :data:`WIRE_CLEARANCE`·R of the wire
    raise ValueError.
    """

    type_name = "loop"
    _linear = ("current_a",)

    def __init__(self, center_m, axis, radius_m, turns, current_a):
        self.center_m = vector3("center_m", center_m)
        self.axis = unit_vector3("axis", axis)
        self.radius_m = _positive("radius_m", radius_m)
        self.turns = _positive("turns", turns)
        self.current_a = float(current_a)
        if not np.isfinite(self.current_a):
            raise ValueError(f"current_a must be finite, got {current_a!r}")

    def _cylindrical(self, points):
        """(ρ_vec, ρ, z, α²) of ``points`` in the loop's frame; ValueError on the wire."""
        relative = points - self.center_m
        z = relative @ self.axis
        rho_vec = relative - z[..., None] * self.axis
        rho = np.sqrt(np.einsum("...i,...i->...", rho_vec, rho_vec))
        alpha2 = (self.radius_m - rho) ** 2 + z**2
        if np.any(alpha2 < (WIRE_CLEARANCE * self.radius_m) ** 2):
            raise ValueError(
                f"field point within {WIRE_CLEARANCE:g}·R of the loop's wire (R = {self.radius_m} m): "
                "the filament field diverges there")
        return rho_vec, rho, z, alpha2

    def field_t(self, points_m):
        rho_vec, rho, z, alpha2 = self._cylindrical(as_points_m(points_m))
        big_r = self.radius_m
        beta2 = (big_r + rho) ** 2 + z**2
        m = 4.0 * big_r * rho / beta2
        p = alpha2 / beta2  # 1 − m, without cancellation near the wire
        k_int = ellipkm1(p)
        e_int = ellipe(m)
        with np.errstate(divide="ignore", invalid="ignore"):
            closed = ((1.0 + p) * e_int - 2.0 * p * k_int) / (m * m * p)
        j = np.where(m < 0.5, (3.0 * np.pi / 16.0) * hyp2f1(1.5, 2.5, 3.0, np.minimum(m, 0.5)), closed)
        ni = MU0 * self.turns * self.current_a
        beta = np.sqrt(beta2)
        b_z = ni / (2.0 * np.pi * alpha2 * beta) * (((big_r - rho) * (big_r + rho) - z**2) * e_int + alpha2 * k_int)
        b_rho_over_rho = 4.0 * ni * big_r**2 * z * j / (np.pi * beta2**2 * beta)
        return b_rho_over_rho[..., None] * rho_vec + b_z[..., None] * self.axis

    def _step_m(self, points, fraction):
        return fraction * np.sqrt(self._cylindrical(points)[3])

    def gradient_t_per_m(self, points_m):
        points = as_points_m(points_m)
        return _central_jacobian(self.field_t, points, self._step_m(points, GRADIENT_STEP))

    def hessian_t_per_m2(self, points_m):
        points = as_points_m(points_m)
        return _central_jacobian(self.gradient_t_per_m, points, self._step_m(points, HESSIAN_STEP))

    def _params(self):
        return {"center_m": self.center_m, "axis": self.axis, "radius_m": self.radius_m,
                "turns": self.turns, "current_a": self.current_a}


def _coaxial_pair(center_m, axis, radius_m, turns, current_a, sign):
    """Loops at center ± (R/2)·axis, currents I (at +) and sign·I (at −)."""
    axis = unit_vector3("axis", axis)
    center = vector3("center_m", center_m)
    half = 0.5 * _positive("radius_m", radius_m) * axis
    return SumSource((CurrentLoop(center + half, axis, radius_m, turns, current_a),
                      CurrentLoop(center - half, axis, radius_m, turns, sign * current_a)))


def helmholtz_pair(center_m, axis, radius_m, turns, current_a) -> SumSource:
    """Helmholtz pair: coaxial loops of radius R at ±R/2 along ``axis``, same current.

    The centre field is (4/5)^(3/2)·μ0·N·I/R along ``axis``, flat to fourth order:
    B_z(z)/B_z(0) = 1 − (144/125)(z/R)⁴ + O((z/R)⁶) on the axis.
    """
    return _coaxial_pair(center_m, axis, radius_m, turns, current_a, +1.0)


def anti_helmholtz_pair(center_m, axis, radius_m, turns, current_a) -> SumSource:
    """Anti-Helmholtz pair: as :func:`helmholtz_pair` but the loop at −R/2 carries −I.

    B = 0 at the centre, where ∂B_z/∂z = 3μ0NI·R²·d / (2(R² + d²/4)^(5/2)) with d = R,
    i.e. 48/(25√5)·μ0·N·I/R² (positive for I > 0), and G_xx = G_yy = −G_zz/2 about the axis.
    """
    return _coaxial_pair(center_m, axis, radius_m, turns, current_a, -1.0)


def solenoid(center_m, axis, radius_m, length_m, turns, current_a, n_loops=8) -> SumSource:
    """A short coil as ``n_loops`` coaxial loops at the midpoints of equal slices of ``length_m``.

    Each loop carries ``turns``/``n_loops`` turns (a layered winding of one radius). With
    ``length_m`` = 0 it is one loop of all the turns.
    """
    axis = unit_vector3("axis", axis)
    length = float(length_m)
    if not (np.isfinite(length) and length >= 0.0):
        raise ValueError(f"length_m must be finite and ≥ 0, got {length_m!r}")
    if int(n_loops) != n_loops or n_loops < 1:
        raise ValueError(f"n_loops must be an integer ≥ 1, got {n_loops!r}")
    n_loops = int(n_loops) if length > 0.0 else 1
    positions = ((np.arange(n_loops) + 0.5) / n_loops - 0.5) * length
    center = vector3("center_m", center_m)
    return SumSource(CurrentLoop(center + z * axis, axis, radius_m, _positive("turns", turns) / n_loops, current_a)
                     for z in positions)


def _sum_of(sources) -> SumSource:
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


def check_keys(what: str, given: dict, builder) -> None:
    """ValueError unless ``given`` holds every required argument of ``builder`` and no other."""
    parameters = inspect.signature(builder).parameters
    unknown = sorted(set(given) - set(parameters))
    missing = [k for k, p in parameters.items() if p.default is inspect.Parameter.empty and k not in given]
    if unknown or missing:
        raise ValueError(f"{what}: unknown keys {unknown}, missing keys {missing}; "
                         f"allowed keys are {list(parameters)}")


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
    return {"type": source.type_name, **{k: _plain(v) for k, v in params.items()}}
