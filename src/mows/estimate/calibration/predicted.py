"""The model of a calibration's ring-downs: the frequency each would show for trial constants.

Every ring-down is the harmonic-balance frequency of the full potential
(:class:`mows.physics.potential.ArcPotential`) in the applied field and gradient plus the
environment field, at the ring-down's decaying amplitude, averaged over amplitude nodes as a
constant-frequency fit averages it (:mod:`mows.physics.ringdown_average`). The fit of the
constants is :mod:`mows.estimate.calibration.fit_constants`.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence

import numpy as np

from mows.estimate.calibration.constants import CalibrationError, CalibrationPoint, KnownConstants, Wiring
from mows.physics import ringdown_average
from mows.physics.pose import probe_axes
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe

AMPLITUDE_NODES = 3


@dataclasses.dataclass(frozen=True)
class Rows:
    """The points as arrays; ``field_t`` and ``gradient_t_per_m`` the applied part, global frame."""

    theta0_rad: np.ndarray
    frequency_hz: np.ndarray
    frequency_std_hz: np.ndarray
    field_t: np.ndarray
    gradient_t_per_m: np.ndarray
    amplitudes_rad: np.ndarray  # (n, q) amplitude nodes of the fit's averaging
    weights: np.ndarray  # (n, q)


def rows_of(points: Sequence[CalibrationPoint], wirings: Mapping[str, Wiring], known: KnownConstants) -> Rows:
    unknown = {p.wiring for p in points} - set(wirings)
    if unknown:
        raise CalibrationError(
            f"points of wirings {sorted(unknown)} but only {sorted(wirings)} are described "
            "(a gradient wiring needs its field per ampere: mows calibrate --gradient-scenario)"
        )
    current = np.array([p.supply_current_a for p in points])
    field = np.array([wirings[p.wiring].field_per_a_t for p in points]) * current[:, None]
    gradient = np.array([wirings[p.wiring].gradient_per_a_t_per_m for p in points]) * current[:, None, None]
    theta0 = np.array([p.theta0_rad for p in points])
    damping = np.array([p.damping_per_s for p in points])
    # the nodes of a swing released at the stop about θ0, scaled to each row's own rest angle by the model
    start = ringdown_average.swing_from_stop_rad(known.theta_stop_rad, 0.0, damping, [p.start_offset_s for p in points])
    amplitudes, weights = ringdown_average.amplitude_nodes(
        theta0, start, damping, np.array([p.duration_s for p in points]), nodes=AMPLITUDE_NODES
    )
    return Rows(
        theta0,
        np.array([p.frequency_hz for p in points]),
        np.array([p.frequency_std_hz for p in points]),
        field,
        gradient,
        amplitudes,
        weights,
    )


def inertia_from(f00_hz: float, spring_nm_per_rad: float, damping_per_s: float) -> float:
    """J = kM/((2π·f00)² + δ²): Eq. 10 with the damping of Eq. S1 kept."""
    return spring_nm_per_rad / ((math.tau * f00_hz) ** 2 + damping_per_s**2)


def frequencies(
    rows: Rows,
    known: KnownConstants,
    f00: float,
    beta0: float,
    environment_t: np.ndarray,
    lever: float,
    stop: float,
    damping: float,
) -> np.ndarray:
    """Ring-down frequencies of every row for the constants given (module docstring of
    :mod:`mows.estimate.calibration.fit_constants`)."""
    spring = f00 * known.moment_am2 / (2.0 * beta0)
    try:
        probe = Probe(
            known.moment_am2,
            spring,
            inertia_from(f00, spring, damping),
            lever,
            known.magnet_mass_kg,
            damping,
            known.theta_stop_rad,
        )
    except ValueError:  # a trial step to unphysical constants: far from every measurement
        return np.full(len(rows.frequency_hz), 1e9)
    axes = probe_axes(rows.theta0_rad)
    field = np.einsum("nij,nj->ni", axes, rows.field_t + environment_t)
    gradient = np.einsum("nai,nij,nbj->nab", axes, rows.gradient_t_per_m, axes)
    q = rows.amplitudes_rad.shape[1]
    potential = ArcPotential.from_local_field(probe, np.repeat(field, q, 0), np.repeat(gradient, q, 0))
    # The nodes scale with the start swing: θmax of a ring-down released at the stop in the row's
    # own potential (0: on the stop).
    swing = np.nan_to_num(ArcPotential.from_local_field(probe, field, gradient).start_swing_rad(stop))
    scale = swing[:, None] / known.theta_stop_rad
    per_node = potential.frequency_hz((scale * rows.amplitudes_rad).reshape(-1)).reshape(-1, q)
    return (rows.weights * per_node).sum(-1)
