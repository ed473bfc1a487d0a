"""Field sources with closed-form derivatives: the :class:`FieldSource` type, superposition
(:class:`SumSource`), :class:`UniformField`, :class:`LinearGradient` and :class:`PointDipole`.

Every source gives the field B (tesla), its gradient G[i, j] = ∂B_i/∂x_j (T/m) and its
Hessian H[i, j, k] = ∂²B_i/∂x_j∂x_k (T/m²) at points of shape (..., 3), vectorised over the
leading dimensions. Outside the sources ∇·B = 0 and ∇×B = 0, so G is symmetric and
traceless and H is symmetric in all three indices and traceless in any pair. ``a + b``
superposes sources, ``source.scaled(k)`` multiplies one by k (a coil's field per ampere times
its current). Current loops are in :mod:`mows.physics.loops`; :mod:`mows.physics.field`
gathers all sources and gives their YAML form.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import scipy.constants
from numpy.typing import ArrayLike

from mows.physics import ranges
from mows.physics.schema import as_points_m, plain, vector3

MU0 = scipy.constants.mu_0  # T·m/A (CODATA 2022 in scipy 1.17)
MU0_OVER_4PI = MU0 / (4.0 * np.pi)

# A gradient tensor is accepted as symmetric and traceless to this fraction of its norm.
MAXWELL_RTOL = 1e-9


class FieldSource:
    """A static field source. Subclasses implement the three derivatives of order 0, 1, 2.

    Parameters whose names are in ``_linear`` scale with the field (:meth:`scaled`);
    ``_params`` gives the constructor arguments (:func:`mows.physics.field.source_to_dict`, ``repr``).
    """

    type_name = ""
    _linear: tuple[str, ...] = ()

    def field_t(self, points_m: ArrayLike) -> np.ndarray:
        """B at ``points_m`` (..., 3), tesla, shape (..., 3)."""
        raise NotImplementedError

    def gradient_t_per_m(self, points_m: ArrayLike) -> np.ndarray:
        """G[..., i, j] = ∂B_i/∂x_j at ``points_m``, T/m, shape (..., 3, 3)."""
        raise NotImplementedError

    def hessian_t_per_m2(self, points_m: ArrayLike) -> np.ndarray:
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

    def __add__(self, other: object) -> FieldSource:
        if not isinstance(other, FieldSource):
            return NotImplemented
        return SumSource(_terms(self) + _terms(other))

    def __radd__(self, other: object) -> FieldSource:
        # Lets the built-in sum() start from 0.
        if isinstance(other, (int, float)) and other == 0:
            return self
        return NotImplemented

    def __repr__(self) -> str:
        args = ", ".join(f"{k}={plain(v)!r}" for k, v in self._params().items())
        return f"{type(self).__name__}({args})"


def _terms(source: FieldSource) -> tuple:
    return source.sources if isinstance(source, SumSource) else (source,)


class SumSource(FieldSource):
    """Superposition of ``sources`` (an empty sum is the zero field)."""

    type_name = "sum"

    def __init__(self, sources: Iterable[FieldSource] = ()) -> None:
        self.sources = tuple(sources)
        for source in self.sources:
            if not isinstance(source, FieldSource):
                raise ValueError(f"sources must be FieldSource objects, got {source!r}")

    def _total(self, method: str, points_m: ArrayLike, rank: int) -> np.ndarray:
        points = as_points_m(points_m)
        total = np.zeros(points.shape + (3,) * rank)
        for source in self.sources:
            total = total + getattr(source, method)(points)
        return total

    def field_t(self, points_m: ArrayLike) -> np.ndarray:
        return self._total("field_t", points_m, 0)

    def gradient_t_per_m(self, points_m: ArrayLike) -> np.ndarray:
        return self._total("gradient_t_per_m", points_m, 1)

    def hessian_t_per_m2(self, points_m: ArrayLike) -> np.ndarray:
        return self._total("hessian_t_per_m2", points_m, 2)

    def _params(self) -> dict:
        return {"sources": self.sources}

    def scaled(self, factor: float) -> SumSource:
        return SumSource(s.scaled(factor) for s in self.sources)


class UniformField(FieldSource):
    """The same field ``field_t`` (tesla, 3-vector) everywhere."""

    type_name = "uniform"
    _linear = ("field_t",)

    def __init__(self, field_t: ArrayLike) -> None:
        self.uniform_t = vector3("field_t", field_t)
        ranges.check("field_t", float(np.linalg.norm(self.uniform_t)), "|field_t|")

    def field_t(self, points_m: ArrayLike) -> np.ndarray:
        return np.broadcast_to(self.uniform_t, as_points_m(points_m).shape).copy()

    def gradient_t_per_m(self, points_m: ArrayLike) -> np.ndarray:
        return np.zeros(as_points_m(points_m).shape + (3,))

    def hessian_t_per_m2(self, points_m: ArrayLike) -> np.ndarray:
        return np.zeros(as_points_m(points_m).shape + (3, 3))

    def _params(self) -> dict:
        return {"field_t": self.uniform_t}


class LinearGradient(FieldSource):
    """B(x) = B0 + G·(x − x0): a constant gradient ``gradient_t_per_m`` G[i, j] = ∂B_i/∂x_j.

    G must be symmetric (∇×B = 0) and traceless (∇·B = 0) to a fraction
    :data:`MAXWELL_RTOL` of its Frobenius norm; otherwise ValueError.
    """

    type_name = "linear_gradient"
    _linear = ("gradient_t_per_m", "field_at_origin_t")

    def __init__(
        self,
        gradient_t_per_m: ArrayLike,
        origin_m: ArrayLike = (0.0, 0.0, 0.0),
        field_at_origin_t: ArrayLike = (0.0, 0.0, 0.0),
    ) -> None:
        g = np.array(gradient_t_per_m, dtype=float)
        if g.shape != (3, 3) or not np.all(np.isfinite(g)):
            raise ValueError(f"gradient_t_per_m must be a finite 3×3 matrix, got {gradient_t_per_m!r}")
        norm = np.linalg.norm(g)
        antisymmetric = np.linalg.norm(g - g.T) / 2.0
        if antisymmetric > MAXWELL_RTOL * norm:
            raise ValueError(
                f"gradient_t_per_m is not symmetric (antisymmetric part {antisymmetric:.3g} T/m, "
                f"norm {norm:.3g} T/m): ∇×B would not vanish in free space"
            )
        if abs(np.trace(g)) > MAXWELL_RTOL * norm:
            raise ValueError(
                f"gradient_t_per_m is not traceless (trace {np.trace(g):.3g} T/m, norm {norm:.3g} T/m): "
                "∇·B would not vanish"
            )
        g.setflags(write=False)
        self.tensor_t_per_m = g
        self.origin_m = vector3("origin_m", origin_m)
        self.field_at_origin_t = vector3("field_at_origin_t", field_at_origin_t)

    def field_t(self, points_m: ArrayLike) -> np.ndarray:
        return self.field_at_origin_t + (as_points_m(points_m) - self.origin_m) @ self.tensor_t_per_m.T

    def gradient_t_per_m(self, points_m: ArrayLike) -> np.ndarray:
        return np.broadcast_to(self.tensor_t_per_m, as_points_m(points_m).shape + (3,)).copy()

    def hessian_t_per_m2(self, points_m: ArrayLike) -> np.ndarray:
        return np.zeros(as_points_m(points_m).shape + (3, 3))

    def _params(self) -> dict:
        return {
            "gradient_t_per_m": self.tensor_t_per_m,
            "origin_m": self.origin_m,
            "field_at_origin_t": self.field_at_origin_t,
        }


def _dipole_offset(moment_am2: ArrayLike, offset_m: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """m, r, r², m·r for the dipole formulas, broadcast together; ValueError at r = 0."""
    r = np.asarray(offset_m, dtype=float)
    m = np.broadcast_to(np.asarray(moment_am2, dtype=float), np.broadcast_shapes(r.shape, np.shape(moment_am2)))
    r2 = np.einsum("...i,...i->...", r, r)
    if np.any(r2 == 0.0):
        raise ValueError("a field point coincides with a point dipole, where its field is undefined")
    return m, r, r2, np.einsum("...i,...i->...", m, r)


def dipole_field_t(moment_am2: ArrayLike, offset_m: ArrayLike) -> np.ndarray:
    """Exact field of point dipoles, B = μ0/(4π)·(3(m·r)r/r⁵ − m/r³), tesla.

    ``moment_am2`` (..., 3) in A·m², ``offset_m`` (..., 3) = field point − dipole position;
    the two broadcast, so a moving dipole sampled in time is one call (Eq. S8 before its
    far-field reduction).
    """
    m, r, r2, mr = _dipole_offset(moment_am2, offset_m)
    inv_r3 = r2**-1.5
    return MU0_OVER_4PI * (3.0 * (mr * inv_r3 / r2)[..., None] * r - inv_r3[..., None] * m)


def _symmetrised(t: np.ndarray) -> np.ndarray:
    """t_ijk + t_jik + t_kji over the last three axes (t symmetric in j, k)."""
    return t + np.swapaxes(t, -3, -2) + np.swapaxes(t, -3, -1)


class PointDipole(FieldSource):
    """Point dipole of moment ``moment_am2`` (A·m²) at ``position_m``; exact derivatives."""

    type_name = "dipole"
    _linear = ("moment_am2",)

    def __init__(self, moment_am2: ArrayLike, position_m: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        self.moment_am2 = vector3("moment_am2", moment_am2)
        self.position_m = vector3("position_m", position_m)

    def field_t(self, points_m: ArrayLike) -> np.ndarray:
        return dipole_field_t(self.moment_am2, as_points_m(points_m) - self.position_m)

    def gradient_t_per_m(self, points_m: ArrayLike) -> np.ndarray:
        # G_ij = 3μ0/(4π r⁵)·[m_i r_j + m_j r_i + (m·r)δ_ij − 5(m·r) r_i r_j / r²]
        m, r, r2, mr = _dipole_offset(self.moment_am2, as_points_m(points_m) - self.position_m)
        outer = m[..., :, None] * r[..., None, :]
        bracket = (
            outer
            + np.swapaxes(outer, -1, -2)
            + mr[..., None, None] * np.eye(3)
            - 5.0 * (mr / r2)[..., None, None] * r[..., :, None] * r[..., None, :]
        )
        return 3.0 * MU0_OVER_4PI * r2[..., None, None] ** -2.5 * bracket

    def hessian_t_per_m2(self, points_m: ArrayLike) -> np.ndarray:
        # ∂_k of G_ij: 3μ0/(4π)·{Σ m_i δ_jk /r⁵ − 5 Σ [m_i r_j r_k + (m·r) r_i δ_jk] /r⁷
        #                       + 35 (m·r) r_i r_j r_k /r⁹}, Σ over the three index placements.
        m, r, r2, mr = _dipole_offset(self.moment_am2, as_points_m(points_m) - self.position_m)
        eye = np.eye(3)
        rr = r[..., :, None] * r[..., None, :]
        m_delta = _symmetrised(m[..., :, None, None] * eye)
        mixed = _symmetrised(
            m[..., :, None, None] * rr[..., None, :, :] + mr[..., None, None, None] * r[..., :, None, None] * eye
        )
        rrr = r[..., :, None, None] * rr[..., None, :, :]
        inv_r2 = (1.0 / r2)[..., None, None, None]
        return (
            3.0
            * MU0_OVER_4PI
            * r2[..., None, None, None] ** -2.5
            * (m_delta - 5.0 * inv_r2 * mixed + 35.0 * inv_r2**2 * mr[..., None, None, None] * rrr)
        )

    def _params(self) -> dict:
        return {"moment_am2": self.moment_am2, "position_m": self.position_m}
