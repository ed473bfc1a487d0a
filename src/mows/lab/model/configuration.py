"""The per-row physics configuration that effects edit.

A :class:`Configuration` describes, for every row of a measurement table, what the probe
feels: the orientation θ0, the field, gradient and Hessian at the magnet (global frame), which
of their probe-frame components act, gravity, the spring, where the magnet and the pivot sit,
and how the frequency is read out (amplitude averaging, damping). The base model switches on
only what Eq. 6 contains: Bx' and Gx'x'. For such a configuration the potential along the arc is

    U(θ) = ½·kM·θ² − m·cos θ·(Bx' + l·Gx'x'·(cos θ − 1)),

so U'(0) = 0 and U''(0) = kM + m·Bx' + l·m·Gx'x' exactly: Eq. 6, f = f00·√(k/kM). Its
frequency through the full potential is :mod:`mows.lab.model.factors`.

The start swing of each ring-down (what the finite-amplitude readout averages from) is physics,
not a per-fit number: every ring-down starts at the housing stop, so its swing turns at
θstop − |θs| from the rest angle θs that the configuration's own field (in full: the lever
deflects by By' whatever else the model holds) gives the potential. The fit reports the swing's
first harmonic, which a lopsided potential puts up to 1 % (0.16° at 3.4 mT) beyond that distance
(:meth:`mows.physics.potential.ArcPotential.start_swing_rad`). The stop is one
number for the table (the probe's ``theta_stop_rad``, moved by the ``housing_stop`` effect). A
table's ``amplitude_deg`` is evidence used where it is trusted (:func:`amplitude_evidence_rad`).
"""

from __future__ import annotations

import dataclasses
import math
import weakref
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from mows.lab.data.table import FIELD, GRADIENT
from mows.physics import ringdown_average
from mows.physics.pose import STANDARD_GRAVITY_M_PER_S2, probe_axes
from mows.physics.potential import (
    DEFAULT_HALF_WIDTH_RAD,
    LOCAL_NODES,
    ArcPotential,
    arc_displacement_m,
    chebyshev_nodes_rad,
)
from mows.physics.probe import Probe
from mows.physics.schema import FloatOrArray, Vector

if TYPE_CHECKING:
    from mows.lab.data.table import MeasurementTable


@dataclasses.dataclass
class Configuration:
    """What each of n rows feels. Arrays are per row; vectors and tensors in the global frame.

    Attributes
    ----------
    theta0_rad : (n,) orientation of the probe axis x'.
    field_t, gradient_t_per_m, hessian_t_per_m2 : (n, 3), (n, 3, 3), (n, 3, 3, 3) or None.
    moment_factor : m_effective / m, one or (n,) per row (calibration error of m/kM, plugins).
    transverse : weight of the gradient components other than Gx'x' (0 in Eq. 6, 1 in full).
    deflection : blend weight of By' (the static deflection), 0 off, 1 exact.
    gravity_m_per_s2 : (n, 3) or None; only its in-plane part acts.
    spring_nm_per_rad : (n,) kM per row (temperature, drift, plugin stiffness).
    amplitude : blend weight of the finite-amplitude readout, 0 off, 1 exact.
    start_evidence_rad : (n,) start swings the table gives and the lab uses, NaN where the stop decides.
    stop_rad : the housing stop every ring-down starts from (one for the table).
    ringdown_damping_per_s, ringdown_duration_s : (n,) the ring-down.
    damping : blend weight of the damped form of Eq. S1 with ``damping_per_s`` per row.
    frequency_hz : (n,) additive frequency contributions.
    neighbour_field_t, neighbour_gradient_t_per_m : (n, 3), (n, 3, 3) or None: the other probes'
        magnets' field and gradient, which act in full whatever ``transverse`` and ``deflection``
        say of the reference (their Hessian is in ``hessian_t_per_m2``).
    energy_j : (n, LOCAL_NODES) or None: energy added to U(θ) at the potential's nodes.
    magnet_offset_m : (n, 3) or None: the magnet's position from (l, 0, 0) in the lever's frame
        (along, across, normal), turning with the lever (:func:`mows.physics.potential.arc_displacement_m`).
    pivot_offset_m : (n, 3) or None: the pivot's position from where the reference puts it,
        global frame. The reference is given at the nominal magnet position (:meth:`probe_frame`).
    """

    theta0_rad: np.ndarray
    field_t: np.ndarray
    gradient_t_per_m: np.ndarray
    spring_nm_per_rad: np.ndarray
    start_evidence_rad: np.ndarray
    stop_rad: float
    ringdown_damping_per_s: np.ndarray
    ringdown_duration_s: np.ndarray
    damping_per_s: np.ndarray
    frequency_hz: np.ndarray
    hessian_t_per_m2: np.ndarray | None = None
    gravity_m_per_s2: np.ndarray | None = None
    moment_factor: float | np.ndarray = 1.0
    transverse: float = 0.0
    deflection: float = 0.0
    amplitude: float = 0.0
    damping: float = 0.0
    neighbour_field_t: np.ndarray | None = None
    neighbour_gradient_t_per_m: np.ndarray | None = None
    energy_j: np.ndarray | None = None
    magnet_offset_m: np.ndarray | None = None
    pivot_offset_m: np.ndarray | None = None

    @classmethod
    def base(cls, table: MeasurementTable, probe: Probe) -> Configuration:
        """Eq. 6 with the table's reference field and gradient."""
        n = len(table)
        ringdown_damping = table.columns.get("damping_per_s", np.full(n, probe.damping_per_s))
        duration = table.columns.get("duration_s", default_window_s(table))
        return cls(
            theta0_rad=table.theta0_rad.copy(),
            field_t=table.field_t,
            gradient_t_per_m=table.gradient_t_per_m,
            spring_nm_per_rad=np.full(n, probe.spring_nm_per_rad),
            start_evidence_rad=amplitude_evidence_rad(table, probe),
            stop_rad=probe.theta_stop_rad,
            ringdown_damping_per_s=ringdown_damping,
            ringdown_duration_s=duration,
            damping_per_s=np.full(n, probe.damping_per_s),
            frequency_hz=np.zeros(n),
        )

    def per_row(self) -> dict[str, np.ndarray]:
        """{field name: its per-row array} (``moment_factor`` only when it is one per row)."""
        n = len(self.theta0_rad)
        found = {}
        for field in dataclasses.fields(self):
            values = getattr(self, field.name)
            if isinstance(values, np.ndarray) and values.ndim and len(values) == n:
                found[field.name] = values
        return found

    def rows(self, index: np.ndarray) -> Configuration:
        """The configuration of the rows ``index`` (indices or a boolean mask)."""
        return dataclasses.replace(self, **{name: values[index] for name, values in self.per_row().items()})

    def start_swing_rad(self, potential: ArcPotential) -> np.ndarray:
        """Each ring-down's start swing in ``potential``: the evidence where the lab uses it, else
        θmax of a swing released at the stop (:meth:`ArcPotential.start_swing_rad`, module
        docstring)."""
        from_stop = np.nan_to_num(potential.start_swing_rad(self.stop_rad))  # 0: on the stop
        return np.where(np.isfinite(self.start_evidence_rad), self.start_evidence_rad, from_stop)

    def probe_frame(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
        """(axes, field', gradient', Hessian') at the magnet's rest position, with axes (n, 3, 3)
        holding rows x', y', z'. Where the magnet or the pivot is moved (by d from where the
        reference is given), the reference's quadratic expansion in full gives the field there,
        B + G·d + ½·H:d d, and the gradient G + H·d, whatever the model keeps of them."""
        axes = probe_axes(self.theta0_rad)
        field, gradient = in_probe_frame(axes, self.field_t, self.gradient_t_per_m)
        hessian = (
            None
            if self.hessian_t_per_m2 is None
            else np.einsum("nai,nbj,nck,nijk->nabc", axes, axes, axes, self.hessian_t_per_m2, optimize=True)
        )
        moved = self.rest_offset_m(axes)
        if moved is not None:
            field = field + np.einsum("nij,nj->ni", gradient, moved)
            if hessian is not None:
                field = field + 0.5 * np.einsum("nijk,nj,nk->ni", hessian, moved, moved)
                gradient = gradient + np.einsum("nijk,nk->nij", hessian, moved)
        return axes, field, gradient, hessian

    def rest_offset_m(self, axes: np.ndarray) -> np.ndarray | None:
        """d (n, 3), probe frame: the magnet's rest position from the nominal one, the pivot's
        offset plus the magnet's on the lever; None where neither is moved."""
        if self.magnet_offset_m is None and self.pivot_offset_m is None:
            return None
        pivot = 0.0 if self.pivot_offset_m is None else np.einsum("nij,nj->ni", axes, self.pivot_offset_m)
        return np.asarray(pivot + (0.0 if self.magnet_offset_m is None else self.magnet_offset_m), float)


@dataclasses.dataclass(frozen=True)
class LeverArc:
    """Where the magnet is along its swing, for an energy a plugin adds (``energy_j``).

    Per row and deflection θ at the potential's nodes (m = LOCAL_NODES), all in the probe frame
    (x' along the undeflected lever): ``theta_rad`` (m,), ``direction`` (m, 3) the moment's
    unit vector u(θ) = (cos θ, sin θ, 0), ``displacement_m`` (n, m, 3) the magnet's
    δr = l·(cos θ − 1, sin θ, 0) from its rest position (on a moved magnet:
    :func:`mows.physics.potential.arc_displacement_m`), ``field_t`` (n, m, 3) the field there
    (B + G·δr + ½·H:δr δr of the configuration, the reference with the effects applied before
    the plugin, at the magnet's rest position: :meth:`Configuration.probe_frame`),
    ``gradient_t_per_m`` (n, 3, 3) at the rest position, ``moment_am2`` (n, 1) with
    the moment's scale, and ``theta0_rad`` (n, 1). Per-row arrays have a trailing axis of 1 (or
    the nodes'), so that ``-0.5 * alpha * (arc.field_t @ ...)`` broadcasts to (n, m)."""

    theta_rad: np.ndarray
    direction: np.ndarray
    displacement_m: np.ndarray
    field_t: np.ndarray
    gradient_t_per_m: np.ndarray
    moment_am2: np.ndarray
    theta0_rad: np.ndarray

    @classmethod
    def of(cls, config: Configuration, probe: Probe) -> LeverArc:
        _, field, gradient, hessian = config.probe_frame()
        theta = chebyshev_nodes_rad(DEFAULT_HALF_WIDTH_RAD, LOCAL_NODES)
        direction = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], -1)
        offset = arc_displacement_m(theta, probe.lever_m, config.magnet_offset_m)
        displacement = np.broadcast_to(offset, (len(field), len(theta), 3))
        along = field[:, None, :] + np.einsum("nij,nmj->nmi", gradient, displacement)
        if hessian is not None:
            along = along + 0.5 * np.einsum("nijk,nmj,nmk->nmi", hessian, displacement, displacement)
        moment = probe.moment_am2 * np.broadcast_to(np.asarray(config.moment_factor, float), (len(field),))
        return cls(theta, direction, displacement, along, gradient, moment[:, None], config.theta0_rad[:, None])


def in_probe_frame(
    axes: np.ndarray, field_t: np.ndarray, gradient_t_per_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Global-frame fields (n, 3) and gradients (n, 3, 3) in the probe frames ``axes`` (n, 3, 3)."""
    return np.einsum("nij,nj->ni", axes, field_t), np.einsum("nai,nij,nbj->nab", axes, gradient_t_per_m, axes)


def default_window_s(table: MeasurementTable) -> np.ndarray:
    """The ring-down's fit window where the table has no ``duration_s``: the paper's 60 periods,
    of the mean measured frequency of the rows that ring down alike (equal θ0, reference field
    and gradient, and ``amplitude_deg`` and ``damping_per_s`` where the table has them). The
    window is then one per configuration, as the physics has it, rather than following each
    row's noise (1e-5 of the window at σ = 1 mHz and 100 Hz, far below what moves the averaged
    frequency), and the rows of a configuration share their amplitude nodes."""
    if table not in _WINDOW:
        names = ["theta0_deg", *FIELD, *GRADIENT, "amplitude_deg", "damping_per_s"]
        _, inverse = distinct_rows_of([table.columns[name] for name in names if table.has(name)])
        mean_hz = np.bincount(inverse, table.f_hz) / np.bincount(inverse)
        _WINDOW[table] = ringdown_average.default_duration_s(mean_hz[inverse])
    return _WINDOW[table]


# table → its default ring-down windows (s)
_WINDOW: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def distinct_rows_of(keys: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(first, inverse): a row of each kind and, for every row, the index of its kind in
    ``first``; rows are of one kind when they are bitwise equal in every array of ``keys``
    (each (n,) or (n, …))."""
    n = len(keys[0])
    words = [np.ascontiguousarray(np.asarray(key, float).reshape(n, -1)).view(np.uint64) for key in keys]
    columns = [column for block in words for column in block.T]
    # A hash of each row's bits groups fast; the groups are then checked bit for bit, column by
    # column (a long table is never copied whole), and only a collision (rows of one hash that
    # differ) falls back to sorting the rows themselves.
    if len(columns) <= len(_HASH_MULTIPLIERS):
        hashed = np.zeros(n, np.uint64)
        with np.errstate(over="ignore"):
            for column, multiplier in zip(columns, _HASH_MULTIPLIERS):
                # Folding the high half in first: a sign flip in two columns (a field reversed)
                # would otherwise add 2^63·(odd + odd) ≡ 0 and collide.
                hashed += (column ^ (column >> np.uint64(32))) * multiplier
        _, first, inverse = np.unique(hashed, return_index=True, return_inverse=True)
        inverse = inverse.ravel()
        if all(np.array_equal(column, column[first][inverse]) for column in columns):
            return first, inverse
    rows = np.ascontiguousarray(np.stack(columns, -1))
    _, first, inverse = np.unique(
        rows.view(np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))).ravel(),
        return_index=True,
        return_inverse=True,
    )
    return first, inverse.ravel()


# Odd 64-bit multipliers of the row hash (fixed: the grouping is the same in every run).
_HASH_MULTIPLIERS = np.random.default_rng(0).integers(1, 2**63, 64, dtype=np.uint64) * np.uint64(2) + np.uint64(1)


# table → {probe: start swings the lab takes from the table's amplitude_deg}
_EVIDENCE: weakref.WeakKeyDictionary[MeasurementTable, dict[Probe, np.ndarray]] = weakref.WeakKeyDictionary()


def amplitude_evidence_rad(table: MeasurementTable, probe: Probe) -> np.ndarray:
    """The start swings (n,) the lab takes from the table, NaN where the stop decides.

    An external table's ``amplitude_deg`` is the user's statement of how the ring-downs were
    excited (a sweep at half the stop, say): used as given. Our own tables' column is an
    estimate pooled from single fits (:func:`mows.lab.data.intake.tool_table`): where it is right
    it equals the stop less the deflection, and where it is not (strong fields) 0.4° of it moves
    a 3.4 mT row by 3 mHz, ten times its σ; so the stop decides every row of our tables, and
    the column stays a covariate. Without the column the stop decides every row."""
    cached = _EVIDENCE.setdefault(table, {})
    if probe not in cached:
        given = table.amplitude_rad if table.amplitude_rad is not None and not table.written_by_mows else None
        cached[probe] = np.full(len(table), np.nan) if given is None else given
    return cached[probe]


def standard_gravity_vector(down_x: FloatOrArray, down_y: FloatOrArray) -> np.ndarray:
    """In-plane gravity g·(down_x, down_y, 0), m/s² (the normal component does not act)."""
    return STANDARD_GRAVITY_M_PER_S2 * np.array([down_x, down_y, 0.0])


def rotation_matrix(rotation_vector: Vector) -> np.ndarray:
    """Rodrigues' rotation matrix of a rotation vector (axis × angle, rad)."""
    vector = np.asarray(rotation_vector, float)
    angle = math.sqrt(float(vector @ vector))
    if angle == 0.0:
        return np.eye(3)
    k = vector / angle
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(angle) * cross + (1 - math.cos(angle)) * cross @ cross
