"""The per-row physics configuration that effects edit, and its frequency through the potential.

A :class:`Configuration` describes, for every row of a measurement table, what the probe
feels: the orientation θ0, the field, gradient and Hessian at the magnet (global frame), which
of their probe-frame components act, gravity, the spring, and how the frequency is read out
(amplitude averaging, damping). The base model switches on only what Eq. 6 contains: Bx' and
Gx'x'. For such a configuration the potential along the arc is

    U(θ) = ½·kM·θ² − m·cos θ·(Bx' + l·Gx'x'·(cos θ − 1)),

so U'(0) = 0 and U''(0) = kM + m·Bx' + l·m·Gx'x' exactly: Eq. 6, f = f00·√(k/kM).

:func:`frequency_factor` evaluates a configuration with
:meth:`mows.physics.potential.ArcPotential.from_local_field` (the field's quadratic expansion along the
lever's arc, exact for the quadratic field the lab describes): exact rest angle (Newton on
U'(θ) = 0 from θ = 0), stiffness U''(θs), and harmonic balance at the ring-down's
amplitude nodes (:mod:`mows.physics.ringdown_average`). It returns h and c with

    f = f00·h + c,

so that the fitted f00 enters linearly (c holds additive frequency contributions of plugins).

The start swing of each ring-down (what the finite-amplitude readout averages from) is physics,
not a per-fit number: every ring-down starts at the housing stop, so its swing turns at
θstop − |θs| from the rest angle θs that the configuration's own field (in full: the lever
deflects by By' whatever else the model holds) gives the potential. The fit reports the swing's
first harmonic, which a lopsided potential puts up to 1 % (0.16° at 3.4 mT) beyond that distance
(:meth:`mows.physics.potential.ArcPotential.start_swing_rad`). The stop is one
number for the table (the probe's ``theta_stop_rad``, moved by the ``housing_stop`` effect). A
table's ``amplitude_deg`` is evidence used where it is trusted (:func:`amplitude_evidence_rad`).

Two effects are quadratic in their natural size (the static deflection adds ≈ (m·By')²/k;
the finite amplitude adds ∝ A²); they are applied as strengths that blend the exact result with
and without them, k = k_off + λ·(k_on − k_off), so that they are linear in λ near 0 (score tests)
while λ = 1 is the exact physics, interactions included.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import math
import weakref
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from mows.lab.data.table import FIELD, GRADIENT
from mows.physics import ringdown_average
from mows.physics.pose import STANDARD_GRAVITY_M_PER_S2, probe_axes
from mows.physics.potential import DEFAULT_HALF_WIDTH_RAD, LOCAL_NODES, ArcPotential, chebyshev_nodes_rad
from mows.physics.probe import Probe
from mows.physics.schema import FloatOrArray, Vector

if TYPE_CHECKING:
    from mows.lab.data.table import MeasurementTable

SLICE_ROWS = 20_000  # configurations the potential evaluates at once
SPRING_NODES = 5  # nodes in kM of a configuration whose spring drifts from row to row
SPRING_SPREAD = 1e-2  # relative spread of kM up to which h is interpolated between them
CACHED_FACTORS = 64  # configurations whose h is kept (:func:`frequency_factor`)
AmplitudeNodes = Callable[["Configuration", np.ndarray], tuple[np.ndarray, np.ndarray]]


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
        """(axes, field', gradient', Hessian') with axes (n, 3, 3) holding rows x', y', z'."""
        axes = probe_axes(self.theta0_rad)
        field, gradient = in_probe_frame(axes, self.field_t, self.gradient_t_per_m)
        hessian = (
            None
            if self.hessian_t_per_m2 is None
            else np.einsum("nai,nbj,nck,nijk->nabc", axes, axes, axes, self.hessian_t_per_m2, optimize=True)
        )
        return axes, field, gradient, hessian


@dataclasses.dataclass(frozen=True)
class LeverArc:
    """Where the magnet is along its swing, for an energy a plugin adds (``energy_j``).

    Per row and deflection θ at the potential's nodes (m = LOCAL_NODES), all in the probe frame
    (x' along the undeflected lever): ``theta_rad`` (m,), ``direction`` (m, 3) the moment's
    unit vector u(θ) = (cos θ, sin θ, 0), ``displacement_m`` (n, m, 3) the magnet's
    δr = l·(cos θ − 1, sin θ, 0) from its rest position, ``field_t`` (n, m, 3) the field there
    (B + G·δr + ½·H:δr δr of the configuration, the reference with the effects applied before
    the plugin), ``gradient_t_per_m`` (n, 3, 3) at the rest position, ``moment_am2`` (n, 1) with
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
        offset = probe.lever_m * (direction - np.array([1.0, 0.0, 0.0]))
        displacement = np.broadcast_to(offset, (len(field),) + offset.shape)
        along = field[:, None, :] + np.einsum("nij,mj->nmi", gradient, offset)
        if hessian is not None:
            along = along + 0.5 * np.einsum("nijk,mj,mk->nmi", hessian, offset, offset)
        moment = probe.moment_am2 * np.broadcast_to(np.asarray(config.moment_factor, float), (len(field),))
        return cls(theta, direction, displacement, along, gradient, moment[:, None], config.theta0_rad[:, None])


def in_probe_frame(
    axes: np.ndarray, field_t: np.ndarray, gradient_t_per_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Global-frame fields (n, 3) and gradients (n, 3, 3) in the probe frames ``axes`` (n, 3, 3)."""
    return np.einsum("nij,nj->ni", axes, field_t), np.einsum("nai,nij,nbj->nab", axes, gradient_t_per_m, axes)


def frequency_factor(
    config: Configuration, probe: Probe, amplitude_nodes: AmplitudeNodes | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(h, c) with f = f00·h + c for every row (module docstring).

    Rows whose every per-row input is identical have the same h whatever the parameters, so h
    is evaluated once per distinct configuration (:func:`distinct_rows`) and given to each of
    its rows: the cost and the memory of the potential and the amplitude nodes grow with the
    distinct configurations, not with the rows. A spring that drifts from row to row (time,
    temperature) would make every row distinct; within a configuration whose springs spread by
    at most ``SPRING_SPREAD`` of kM, h is a smooth function of the one number kM, evaluated at
    ``SPRING_NODES`` Chebyshev nodes of its range and interpolated (:func:`_spring_plan`).
    ``amplitude_nodes(config, start_rad)`` gives (A_q (n, q), c_q (n, q)) of the
    configuration's ring-downs that start at ``start_rad`` (default: :func:`ringdown_nodes`,
    uncached); used when ``config.amplitude`` ≠ 0.
    """
    key = _physics_key(config, probe)
    if key in _FACTORS:
        _FACTORS.move_to_end(key)
        return _FACTORS[key].copy(), config.frequency_hz
    first, inverse = distinct_rows(config)
    rows, springs, index, weight = _spring_plan(config.spring_nm_per_rad, first, inverse, probe.spring_nm_per_rad)
    evaluated = config.rows(rows)
    evaluated.spring_nm_per_rad = springs
    nodes = amplitude_nodes or ringdown_nodes
    # In slices, so that the potential's work arrays stay bounded where every row differs.
    h = np.concatenate(
        [
            _frequency_factor(evaluated.rows(np.arange(start, min(start + SLICE_ROWS, len(rows)))), probe, nodes)
            for start in range(0, len(rows), SLICE_ROWS)
        ]
    )
    found = np.where(weight != 0.0, h[index] * weight, 0.0).sum(-1)
    _FACTORS[key] = found.copy()
    if len(_FACTORS) > CACHED_FACTORS:
        _FACTORS.popitem(last=False)
    return found, config.frequency_hz


# The h of recent configurations, by their physics (every input but the additive frequency): the
# Jacobian column of a parameter that only adds to f (a plugin's frequency term, a stand-in for
# physics outside the catalog) then costs no evaluation of the potential.
_FACTORS: collections.OrderedDict[bytes, np.ndarray] = collections.OrderedDict()


def _physics_key(config: Configuration, probe: Probe) -> bytes:
    """A digest of everything h depends on: every field of ``config`` but ``frequency_hz``, and the probe."""
    digest = hashlib.blake2b(repr(probe).encode(), digest_size=20)
    for field in dataclasses.fields(config):
        if field.name == "frequency_hz":
            continue
        value = getattr(config, field.name)
        digest.update(field.name.encode())
        if value is None or np.isscalar(value):
            digest.update(repr(value).encode())
        else:
            array = np.ascontiguousarray(value, float)
            digest.update(repr(array.shape).encode())
            digest.update(array.tobytes())
    return digest.digest()


def _spring_plan(
    spring: np.ndarray, first: np.ndarray, inverse: np.ndarray, reference: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(rows, springs, index, weight): the evaluations that give every row's h, and how.

    Evaluation e is row ``rows[e]``'s configuration with kM = ``springs[e]``; row i's h is
    Σ_j weight[i, j]·h[index[i, j]]. A configuration (``first``/``inverse``: groups equal in
    everything but kM) whose springs spread by at most ``SPRING_SPREAD``·``reference`` gets
    ``SPRING_NODES`` Chebyshev nodes over its range and Lagrange weights: h is analytic in kM,
    so the error falls as (spread/2)^K/K! — below 1e-13 of h at the limit. Other rows are
    evaluated at their own kM, once per distinct (configuration, kM)."""
    n, count = len(spring), len(first)
    low, high = np.full(count, np.inf), np.full(count, -np.inf)
    np.minimum.at(low, inverse, spring)
    np.maximum.at(high, inverse, spring)
    interpolated = (high > low) & (high - low <= SPRING_SPREAD * reference)
    index, weight = np.zeros((n, SPRING_NODES), int), np.zeros((n, SPRING_NODES))
    exact = np.flatnonzero(~interpolated[inverse])
    own, own_inverse = distinct_rows_of([inverse[exact], spring[exact]]) if exact.size else (exact, exact)
    index[exact, 0], weight[exact, 0] = own_inverse, 1.0
    groups = np.flatnonzero(interpolated)
    unit = np.cos(np.pi * (np.arange(SPRING_NODES) + 0.5) / SPRING_NODES)
    mid, half = 0.5 * (low + high), 0.5 * (high - low)
    position = np.full(count, -1)
    position[groups] = np.arange(len(groups))
    shared = np.flatnonzero(interpolated[inverse])
    group = inverse[shared]
    index[shared] = len(own) + position[group][:, None] * SPRING_NODES + np.arange(SPRING_NODES)
    weight[shared] = _lagrange_weights((spring[shared] - mid[group]) / half[group], unit)
    rows = np.concatenate([exact[own], np.repeat(first[groups], SPRING_NODES)])
    springs = np.concatenate([spring[exact[own]], (mid[groups, None] + half[groups, None] * unit).ravel()])
    return rows, springs, index, weight


def _lagrange_weights(x: np.ndarray, nodes: np.ndarray) -> np.ndarray:
    """(len(x), len(nodes)): the Lagrange basis polynomials of ``nodes`` at ``x``."""
    weights = np.ones((len(x), len(nodes)))
    for k, node in enumerate(nodes):
        for j, other in enumerate(nodes):
            if j != k:
                weights[:, k] *= (x - other) / (node - other)
    return weights


def distinct_rows(config: Configuration) -> tuple[np.ndarray, np.ndarray]:
    """(first, inverse): a row of each distinct configuration and, for every row, the index of its
    configuration in ``first``. Rows are the same configuration when every per-row input that h
    reads is bitwise equal: not the additive ``frequency_hz``, the ring-down's start and window
    only with the finite-amplitude readout on, its damping only with the damped readout on; and
    not kM, which :func:`_spring_plan` handles."""
    n = len(config.theta0_rad)
    unread = {"frequency_hz", "spring_nm_per_rad"}
    if not config.amplitude:
        unread |= {"start_evidence_rad", "ringdown_damping_per_s", "ringdown_duration_s"}
    if not config.damping:
        unread.add("damping_per_s")
    inputs = [
        np.asarray(values, float).reshape(n, -1) for name, values in config.per_row().items() if name not in unread
    ]
    return distinct_rows_of(inputs)


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


def _frequency_factor(config: Configuration, probe: Probe, amplitude_nodes: AmplitudeNodes) -> np.ndarray:
    """h for every row of ``config`` (:func:`frequency_factor`, without the grouping)."""
    axes, field, gradient, hessian = config.probe_frame()
    factor = np.asarray(config.moment_factor, float)
    factor = factor.reshape(factor.shape + (1,))  # broadcasts over a row's vector components
    along = np.zeros_like(field)
    along[:, 0] = field[:, 0]
    active_gradient = config.transverse * gradient
    active_gradient[:, 0, 0] = gradient[:, 0, 0]
    if config.neighbour_field_t is not None and config.neighbour_gradient_t_per_m is not None:
        neighbour, neighbour_gradient = in_probe_frame(
            axes, config.neighbour_field_t, config.neighbour_gradient_t_per_m
        )
        along, field = along + neighbour, field + neighbour
        active_gradient = active_gradient + neighbour_gradient
    variants = [along] + ([field] if config.deflection else [])
    gravity = None if config.gravity_m_per_s2 is None else np.einsum("nij,nj->ni", axes, config.gravity_m_per_s2)
    local: dict[str, Any] = dict(
        gradient_t_per_m=factor[..., None] * active_gradient,
        hessian_t_per_m2=None if hessian is None else factor[..., None, None] * hessian,
        gravity_m_per_s2=gravity,
        spring_nm_per_rad=config.spring_nm_per_rad,
        energy_j=config.energy_j,
    )
    stiffness = [_rest_stiffness(probe, factor * b, **local) for b in variants]
    h = _readout(config, probe, _blend(stiffness, config.deflection))
    if config.amplitude:
        start = config.start_swing_rad(_potential(probe, factor * field, **local))
        amplitudes, weights = amplitude_nodes(config, start)
        at_amplitude = [_amplitude_stiffness(probe, factor * b, amplitudes, **local) for b in variants]
        averaged = (weights * _readout(config, probe, _blend(at_amplitude, config.deflection))).sum(-1)
        h = h + config.amplitude * (averaged - h)
    return h


def ringdown_nodes(config: Configuration, start_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude nodes (A_q, c_q) of the configuration's ring-downs from ``start_rad``
    (:func:`mows.physics.ringdown_average.amplitude_nodes`)."""
    return ringdown_average.amplitude_nodes(
        config.theta0_rad, start_rad, config.ringdown_damping_per_s, config.ringdown_duration_s
    )


# table → {probe: start swings the lab takes from the table's amplitude_deg}
_EVIDENCE: weakref.WeakKeyDictionary[MeasurementTable, dict[Probe, np.ndarray]] = weakref.WeakKeyDictionary()


def amplitude_evidence_rad(table: MeasurementTable, probe: Probe) -> np.ndarray:
    """The start swings (n,) the lab takes from the table, NaN where the stop decides.

    An external table's ``amplitude_deg`` is the user's statement of how the ring-downs were
    excited (a sweep at half the stop, say): used as given. Our own tables' column is an
    estimate pooled from single fits (:func:`mows.lab.data.table.tool_table`): where it is right
    it equals the stop less the deflection, and where it is not (strong fields) 0.4° of it moves
    a 3.4 mT row by 3 mHz, ten times its σ; so the stop decides every row of our tables, and
    the column stays a covariate. Without the column the stop decides every row."""
    cached = _EVIDENCE.setdefault(table, {})
    if probe not in cached:
        given = table.amplitude_rad if table.amplitude_rad is not None and not table.written_by_mows else None
        cached[probe] = np.full(len(table), np.nan) if given is None else given
    return cached[probe]


def base_start_swing_rad(table: MeasurementTable, probe: Probe) -> np.ndarray:
    """Each row's start swing at the table's reference field and gradient in full and the probe's stop."""
    config = Configuration.base(table, probe)
    _, field, gradient, _ = config.probe_frame()
    return config.start_swing_rad(_potential(probe, field, gradient, None, None, config.spring_nm_per_rad))


def _blend(values: list[np.ndarray], weight: float) -> np.ndarray:
    return values[0] if len(values) == 1 else values[0] + weight * (values[1] - values[0])


def _readout(config: Configuration, probe: Probe, stiffness: np.ndarray) -> np.ndarray:
    """h = f/f00 for stiffness k: √(k/kM) (Eq. 6), blended towards the damped form of Eq. S1,
    √((k/J − δ²)/(kM/J − δ0²)) with δ per row."""
    spring, inertia, damping0 = probe.spring_nm_per_rad, probe.inertia_kgm2, probe.damping_per_s
    squared = stiffness / spring
    if config.damping:
        rows = (slice(None),) + (None,) * (np.ndim(stiffness) - 1)
        damped = (stiffness / inertia - config.damping_per_s[rows] ** 2) / (spring / inertia - damping0**2)
        squared = squared + config.damping * (damped - squared)
    return np.sqrt(np.where(squared > 0, squared, np.nan))


def _potential(
    probe: Probe,
    field: np.ndarray,
    gradient_t_per_m: np.ndarray,
    hessian_t_per_m2: np.ndarray | None,
    gravity_m_per_s2: np.ndarray | None,
    spring_nm_per_rad: np.ndarray,
    energy_j: np.ndarray | None = None,
    repeat: int | None = None,
) -> ArcPotential:
    """ArcPotential.from_local_field for the rows, optionally each repeated ``repeat`` times."""

    def expand(a: np.ndarray | None) -> Any:
        return a if a is None or repeat is None else np.repeat(a, repeat, axis=0)

    return ArcPotential.from_local_field(
        probe,
        expand(field),
        expand(gradient_t_per_m),
        expand(hessian_t_per_m2),
        expand(gravity_m_per_s2),
        spring_nm_per_rad=expand(spring_nm_per_rad),
        energy_j=expand(energy_j),
    )


def _rest_stiffness(probe: Probe, field: np.ndarray, **local: Any) -> np.ndarray:
    """U''(θs) at the exact rest angle (:meth:`ArcPotential.rest_angle_rad`); NaN where unstable."""
    potential = _potential(probe, field, **local)
    theta = potential.rest_angle_rad()
    return np.where(np.isfinite(theta), potential.stiffness_nm_per_rad(np.nan_to_num(theta)), np.nan)


def _amplitude_stiffness(probe: Probe, field: np.ndarray, amplitudes: np.ndarray, **local: Any) -> np.ndarray:
    """Harmonic-balance stiffness k(A) (n, q) at the amplitude nodes."""
    n, q = amplitudes.shape
    potential = _potential(probe, field, repeat=q, **local)
    return potential.effective_stiffness_nm_per_rad(amplitudes.reshape(-1)).reshape(n, q)


def unevaluable_rows(table: MeasurementTable, probe: Probe) -> dict[int, tuple[str, str]]:
    """{row index: (reason, detail)} for the rows where the potential cannot give a frequency with the
    table's reference field and gradient in full (every component, as the physics effects use
    them) at the row's start amplitude: no stable rest angle, a swing |θc| + A beyond the
    interval over which the potential is expanded, or no real frequency. Such rows are left
    out of the fit (:func:`mows.lab.report.lab_report.analyse`), never given a made-up residual."""
    config = Configuration.base(table, probe)
    _, field, gradient, _ = config.probe_frame()
    potential = _potential(probe, field, gradient, None, None, config.spring_nm_per_rad)
    at_rest = potential.rest_angle_rad()
    amplitude = config.start_swing_rad(potential)
    centre = potential.cycle_centre_rad(amplitude)
    config.transverse = config.deflection = config.amplitude = 1.0
    h, _ = frequency_factor(config, probe)
    limit_deg = math.degrees(potential.half_width_rad)
    found = {}
    for row in np.flatnonzero(~np.isfinite(at_rest)):
        found[int(row)] = (
            "no stable rest angle in the reference field (the field spring cancels the mechanical one)",
            f"|B| = {np.linalg.norm(field[row]) * 1e3:.3g} mT",
        )
    for row in np.flatnonzero(np.isfinite(at_rest) & ~np.isfinite(centre)):
        swing = math.degrees(abs(at_rest[row]) + amplitude[row])
        found[int(row)] = (
            f"the swing |θs| + A reaches beyond the ±{limit_deg:.3g}° over which the potential is expanded",
            f"{swing:.3g}°",
        )
    for row in np.flatnonzero(~np.isfinite(h)):
        found.setdefault(int(row), ("the potential gives no real frequency here (k/J ≤ δ²)", ""))
    return dict(sorted(found.items()))


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
