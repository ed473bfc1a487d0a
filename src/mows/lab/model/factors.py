"""A configuration's frequency through the full potential: f = f00·h + c for every row.

:func:`frequency_factor` evaluates a :class:`mows.lab.model.configuration.Configuration` with
:meth:`mows.physics.potential.ArcPotential.from_local_field` (the field's quadratic expansion along the
lever's arc, exact for the quadratic field the lab describes): exact rest angle (Newton on
U'(θ) = 0 from θ = 0), stiffness U''(θs), and harmonic balance at the ring-down's
amplitude nodes (:mod:`mows.physics.ringdown_average`). It returns h and c with

    f = f00·h + c,

so that the fitted f00 enters linearly (c holds additive frequency contributions of plugins).

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
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from mows.lab.model.configuration import Configuration, distinct_rows_of, in_probe_frame
from mows.physics import ringdown_average
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe

if TYPE_CHECKING:
    from mows.lab.data.table import MeasurementTable

SLICE_ROWS = 20_000  # configurations the potential evaluates at once
SPRING_NODES = 5  # nodes in kM of a configuration whose spring drifts from row to row
SPRING_SPREAD = 1e-2  # relative spread of kM up to which h is interpolated between them
CACHED_FACTORS = 64  # configurations whose h is kept at least (:func:`frequency_factor`) …
CACHED_FACTOR_BYTES = 32 * 2**20  # … and more while their h take no more than this
AmplitudeNodes = Callable[[Configuration, np.ndarray], tuple[np.ndarray, np.ndarray]]


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
    cached = _FACTORS.get(key)
    if cached is not None:
        return cached, config.frequency_hz
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
    _FACTORS.put(key, found)
    return found, config.frequency_hz


class _RecentFactors:
    """The h of recent configurations by key, least recently used dropped first: at least
    ``CACHED_FACTORS`` of them, and more while they hold at most ``CACHED_FACTOR_BYTES``
    (a long table's h are large, a short one's many)."""

    def __init__(self) -> None:
        self._found: collections.OrderedDict[bytes, np.ndarray] = collections.OrderedDict()
        self._bytes = 0

    def get(self, key: bytes) -> np.ndarray | None:
        """A copy of the h kept under ``key``, None when there is none."""
        if key not in self._found:
            return None
        self._found.move_to_end(key)
        return self._found[key].copy()

    def put(self, key: bytes, h: np.ndarray) -> None:
        """Keep a copy of ``h`` under ``key`` (which :meth:`get` did not find)."""
        self._found[key] = h.copy()
        self._bytes += h.nbytes
        while len(self._found) > CACHED_FACTORS and self._bytes > CACHED_FACTOR_BYTES:
            _, dropped = self._found.popitem(last=False)
            self._bytes -= dropped.nbytes


# The h of recent configurations, by their physics (every input but the additive frequency): the
# Jacobian column of a parameter that only adds to f (a plugin's frequency term, a stand-in for
# physics outside the catalog) then costs no evaluation of the potential, and the search's many
# fits of models that differ in one effect share the points they step through (a fifth of the
# evaluations of an automatic search on 1000 rows).
_FACTORS = _RecentFactors()


def _physics_key(config: Configuration, probe: Probe) -> bytes:
    """A digest of everything h depends on: every field of ``config`` but ``frequency_hz``, and the probe."""
    # SHA-256: processors hash it in hardware, several times faster than BLAKE2 over the rows' bytes.
    digest = hashlib.sha256(repr(probe).encode())
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
            digest.update(array.data)  # its buffer, not a copy
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
        moved = config.rest_offset_m(axes)  # their Hessian's share is in probe_frame's
        if moved is not None:
            neighbour = neighbour + np.einsum("nij,nj->ni", neighbour_gradient, moved)
        along, field = along + neighbour, field + neighbour
        active_gradient = active_gradient + neighbour_gradient
    gravity = None if config.gravity_m_per_s2 is None else np.einsum("nij,nj->ni", axes, config.gravity_m_per_s2)
    local: dict[str, Any] = dict(
        gradient_t_per_m=factor[..., None] * active_gradient,
        hessian_t_per_m2=None if hessian is None else factor[..., None, None] * hessian,
        gravity_m_per_s2=gravity,
        spring_nm_per_rad=config.spring_nm_per_rad,
        energy_j=config.energy_j,
        magnet_offset_m=config.magnet_offset_m,
    )
    # The potential with the field along the probe, and with the whole field where the deflection
    # is on; each serves the rest stiffness and the amplitude nodes, and the whole field's the
    # start swing (built for it alone where the deflection is off).
    variants = [_potential(probe, factor * b, **local) for b in [along] + ([field] if config.deflection else [])]
    stiffness = [_rest_stiffness(potential) for potential in variants]
    h = _readout(config, probe, _blend(stiffness, config.deflection))
    if config.amplitude:
        whole = variants[-1] if config.deflection else _potential(probe, factor * field, **local)
        start = config.start_swing_rad(whole)
        amplitudes, weights = amplitude_nodes(config, start)
        at_amplitude = [potential.effective_stiffness_nm_per_rad(amplitudes) for potential in variants]
        averaged = (weights * _readout(config, probe, _blend(at_amplitude, config.deflection))).sum(-1)
        h = h + config.amplitude * (averaged - h)
    return h


def ringdown_nodes(config: Configuration, start_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Amplitude nodes (A_q, c_q) of the configuration's ring-downs from ``start_rad``
    (:func:`mows.physics.ringdown_average.amplitude_nodes`)."""
    return ringdown_average.amplitude_nodes(
        config.theta0_rad, start_rad, config.ringdown_damping_per_s, config.ringdown_duration_s
    )


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
    magnet_offset_m: np.ndarray | None = None,
) -> ArcPotential:
    """ArcPotential.from_local_field for the rows."""
    return ArcPotential.from_local_field(
        probe,
        field,
        gradient_t_per_m,
        hessian_t_per_m2,
        gravity_m_per_s2,
        spring_nm_per_rad=spring_nm_per_rad,
        energy_j=energy_j,
        magnet_offset_m=magnet_offset_m,
    )


def _rest_stiffness(potential: ArcPotential) -> np.ndarray:
    """U''(θs) at the exact rest angle (:meth:`ArcPotential.rest_angle_rad`); NaN where unstable."""
    theta = potential.rest_angle_rad()
    return np.where(np.isfinite(theta), potential.stiffness_nm_per_rad(np.nan_to_num(theta)), np.nan)


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
