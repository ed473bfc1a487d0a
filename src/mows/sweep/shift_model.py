"""Rotation-sweep model: Δf(θ0) of a probe turned in an in-plane field and gradient (Eqs. 11, 12, S18).

Turning the probe through θ0 changes which field and gradient components it feels. With the
in-plane field B = (Bx, By) and gradient G (G_ij = ∂B_i/∂x_j; Gs = (Gxx + Gyy)/2,
Gd = (Gxx − Gyy)/2, Gxy), the probe axis x' = (cos θ0, sin θ0) sees

    Bx' = Bx·cos θ0 + By·sin θ0,
    Gx'x' = Gs + Gd·cos 2θ0 + Gxy·sin 2θ0,    Gy'y' = Gs − Gd·cos 2θ0 − Gxy·sin 2θ0.

Two models are offered:

``published``   k = kM + m·Bx' + l·m·Gx'x' in Eq. 6 (the paper's Eqs. 11-12 are its first
                order, with the factor f00 restored, docs/physics.md §8);
``first_principles``  k = U''(θs) of the full potential (docs/physics.md §4) in the local field
                B + G·δr: exact rest angle (static deflection by By'), the lever's transverse
                gradient term. To first order m·l·(Gx'x' − 2Gy'y') = m·l·(−Gs + 3·(Gd·cos 2θ0
                + Gxy·sin 2θ0)): the 2θ0 harmonic is three times the published one, and the
                constant term has the opposite sign.

Both report f = f00·√(k/kM); :mod:`mows.sweep.decompose` fits them to a sweep.

**The field's curvature over the arc.** The stage turns the probe about its magnet's rest
position, and B and G are the field and gradient there. A ring-down swings the magnet along an
arc of the lever, δr ≈ l·(−θ²/2, θ, 0), so the field's second derivatives H_ijk = ∂²B_i/∂x_j∂x_k
add −m·l²·∂²Bx'/∂y'² to the stiffness. Over θ0 that term has two parts. The in-plane harmonic
part of H (H_xxx = −H_xyy = Hc, H_xxy = −H_yyy = Hs: the potential (Hc·Re + Hs·Im)(x + iy)³/6)
gives a 3θ0 harmonic, which the decomposition's ``curvature`` fits: 7 distinct orientations
determine it. The trace part, (H_xxx + H_xyy, H_yxx + H_yyy) = −∂²(Bx, By)/∂z², gives a 1θ0
harmonic that no sweep tells apart from the field: the B reported is B + (l²/4)·∂²(Bx, By)/∂z²
at the magnet's rest position (docs/multi_probe.md gives its size). Without ``curvature`` the
3θ0 term is left in the residual, where unequal σ over the sweep leak it into B.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools

import numpy as np

from mows.physics.frequency import PublishedSweep
from mows.physics.pose import probe_axes
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe
from mows.physics.ringdown_average import amplitude_nodes, swing_about_rest_rad

MODELS = ("first_principles", "published")
PARAMETER_COUNT = 8  # Bx, By, Gs, Gd, Gxy, Δf00, Hc, Hs
# The rest angles the measured swings are tabulated at: a sweep's static deflections are tens of
# mrad; the swing is smooth in them, so linear interpolation over 5 mrad errs by < 0.1 %.
REST_NODES_RAD = np.linspace(-0.1, 0.1, 41)


@dataclasses.dataclass(frozen=True)
class Ringdowns:
    """How a sweep's ring-downs were recorded, for the amplitude-dependent springs.

    Every ring-down starts from the housing stop: at ``stop_amplitude_rad`` from the lever's
    undeflected position, so its swing about the rest angle θs (turned by the perpendicular
    field, docs/physics.md §6.2) is stop − |θs|, which the model computes from its own potential.
    The coils are cut with the lever at the stop; the fit's window starts ``start_offset_s``
    (per point) later, over which the swing decays by e^(−δ·t): 0.5 % over the estimator's
    3 ms skip, 0.13° of a 24° swing, which through the field spring's amplitude dependence
    reads a 3.4 mT field 0.14 µT high (docs/physics.md §6.4).
    ``damping_per_s`` and ``duration_s`` (per point) give the averaging of a constant-frequency
    fit over the decaying swing (:mod:`mows.physics.ringdown_average`), weighted by where in
    the swing the signal carries phase: ``pickup`` (n, K + 1) are the series C_k each fit used
    (:attr:`mows.estimate.ringdown.RingdownFit.pickup`); None assumes Eq. S11 with the paper's
    sensing axis. With the magnet on its lever, the far-field weight misses a first harmonic at
    θ0 = 90° and misplaces that fit's average by 4 % of its amplitude correction.
    """

    stop_amplitude_rad: float
    damping_per_s: np.ndarray
    duration_s: np.ndarray
    pickup: np.ndarray | None = None
    # The swing at each window's start, measured (n,), for ring-downs that do not start from the
    # stop (a multi-tone excitation's; the stop is then not used): from the signal's size through
    # ``pickup`` about the undeflected lever, as the fit that measured it had no rest angle. The
    # model turns it into the swing about its own rest angle (:meth:`start_swing_about_rad`).
    start_swing_rad: np.ndarray | None = None
    start_offset_s: np.ndarray | float = 0.0  # each window's first sample after the coil switch-off
    # The stop's standard uncertainty: one error shared by every ring-down of the sweep
    # (:func:`mows.sweep.decompose.decompose` carries it into the covariance); 0 for a stop taken as exact.
    stop_std_rad: float = 0.0

    def released_swing_rad(self, potential: ArcPotential) -> np.ndarray:
        """The swing at each window's first sample of a ring-down released at the stop: the
        first harmonic of the swing that turns there, decayed over ``start_offset_s``; 0 where
        the stop lies inside the deflection (a trial point the data rule out)."""
        swing = np.nan_to_num(potential.start_swing_rad(self.stop_amplitude_rad))
        return swing * np.exp(-np.asarray(self.damping_per_s, float) * np.asarray(self.start_offset_s, float))

    @functools.cached_property
    def _swing_table_rad(self) -> np.ndarray:
        """(n, REST_NODES_RAD.size): each measured swing about each rest angle of the table, NaN
        until first asked for (:meth:`_swing_cells`). A fit moves each point's rest angle by
        a few mrad, so it asks for two or three nodes of each row, not all 41."""
        rows = np.shape(np.asarray(self.pickup))[0]
        return np.nan * np.ones((rows, REST_NODES_RAD.size))

    @functools.cached_property
    def _swing_tabulated(self) -> np.ndarray:
        """Which cells of :attr:`_swing_table_rad` are computed (a swing may be NaN: no signal)."""
        return np.zeros(self._swing_table_rad.shape, bool)

    def _swing_cells(self, columns: np.ndarray) -> np.ndarray:
        """The table with, for each row r, the nodes ``columns[r]`` and ``columns[r] + 1``
        computed (:func:`mows.physics.ringdown_average.swing_about_rest_rad`, all missing
        cells in one call)."""
        table, done = self._swing_table_rad, self._swing_tabulated
        rows = np.arange(len(table))
        rows, columns = np.concatenate((rows, rows)), np.concatenate((columns, columns + 1))
        missing = ~done[rows, columns]
        if missing.any():
            r, c = rows[missing], columns[missing]
            n = len(table)
            table[r, c] = swing_about_rest_rad(
                np.broadcast_to(np.asarray(self.start_swing_rad, float), (n,))[r],
                np.asarray(self.pickup, complex)[r],
                np.broadcast_to(np.asarray(self.damping_per_s, float), (n,))[r],
                np.broadcast_to(np.asarray(self.duration_s, float), (n,))[r],
                REST_NODES_RAD[c],
            )
            done[r, c] = True
        return table

    def start_swing_about_rad(self, rest_rad) -> np.ndarray:
        """The measured swings (n,) about the rest angles ``rest_rad`` (n,) of the model: the
        signal's size means a swing about the undeflected lever that is a few percent off the
        one about a rest angle of 10 mrad (:func:`mows.physics.ringdown_average.swing_about_rest_rad`,
        tabulated where asked for and interpolated linearly, held at the table's ends). As
        measured without a pickup to convert through."""
        swings = np.asarray(self.start_swing_rad, float)
        if self.pickup is None:
            return swings
        nodes = REST_NODES_RAD
        rest = np.clip(np.nan_to_num(np.broadcast_to(np.asarray(rest_rad, float), swings.shape)), nodes[0], nodes[-1])
        below = np.clip(np.searchsorted(nodes, rest, side="right") - 1, 0, nodes.size - 2)
        weight = (rest - nodes[below]) / (nodes[below + 1] - nodes[below])
        table = self._swing_cells(below)
        rows = np.arange(len(table))
        low, high = table[rows, below], table[rows, below + 1]
        # A weight of 0 or 1 is the node's value, whatever its neighbour (NaN: no signal there).
        return np.where(weight == 0.0, low, np.where(weight == 1.0, high, low + weight * (high - low)))


@dataclasses.dataclass(frozen=True)
class NeighbourFields:
    """What other probes' magnets add at this probe's magnet (its rest position), per point of
    the sweep, global frame: field (n, 3), T; gradient (n, 3, 3), T/m; Hessian (n, 3, 3, 3),
    T/m² (:mod:`mows.sweep.probes`). Known terms of the model, not fitted."""

    field_t: np.ndarray
    gradient_t_per_m: np.ndarray
    hessian_t_per_m2: np.ndarray


def curvature_hessian_t_per_m2(hc_t_per_m2: float, hs_t_per_m2: float) -> np.ndarray:
    """H_ijk = ∂²B_i/∂x_j∂x_k (3, 3, 3) of the potential (Hc·Re + Hs·Im)(x + iy)³/6: the in-plane
    harmonic part of a field's curvature (module docstring), harmonic in 3D, no z components."""
    hessian = np.zeros((3, 3, 3))
    for indices, value in (((0, 0, 0), hc_t_per_m2), ((0, 1, 1), -hc_t_per_m2), ((0, 0, 1), hs_t_per_m2)):
        for permuted in itertools.permutations(indices):
            hessian[permuted] = value
    hessian[1, 1, 1] = -hs_t_per_m2
    return hessian


def local_potential(params, theta0_rad, probe: Probe, neighbours: NeighbourFields | None = None) -> ArcPotential:
    """The potential of each point for params (Bx, By, Gs, Gd, Gxy, Δf00[, Hc, Hs]): the field,
    gradient and in-plane curvature turned into the probe frame (Gzz = −(Gxx + Gyy) by ∇·B = 0),
    plus the ``neighbours``' fields when given."""
    bx, by, gs, gd, gxy = params[:5]
    theta0 = np.asarray(theta0_rad, float)
    rotation = probe_axes(theta0)
    gxx, gyy = gs + gd, gs - gd
    global_field = np.array([bx, by, 0.0])
    global_gradient = np.array([[gxx, gxy, 0.0], [gxy, gyy, 0.0], [0.0, 0.0, -(gxx + gyy)]])
    global_hessian = curvature_hessian_t_per_m2(*params[6:8]) if len(params) > 6 and np.any(params[6:8]) else None
    if neighbours is not None:
        global_field = global_field + neighbours.field_t
        global_gradient = global_gradient + neighbours.gradient_t_per_m
        known = neighbours.hessian_t_per_m2
        global_hessian = known if global_hessian is None else known + global_hessian
    field = np.einsum("...ij,...j->...i", rotation, global_field)
    gradient = rotation @ global_gradient @ np.swapaxes(rotation, -1, -2)
    if global_hessian is None:
        return ArcPotential.from_local_field(probe, field, gradient)
    hessian = np.einsum("...ia,...abc,...jb,...kc->...ijk", rotation, global_hessian, rotation, rotation)
    return ArcPotential.from_local_field(probe, field, gradient, hessian)


def model_shift_hz(
    params,
    theta0_rad,
    probe: Probe,
    f00_hz: float,
    model: str,
    ringdowns: Ringdowns | None = None,
    neighbours: NeighbourFields | None = None,
):
    """Δf(θ0) for params (Bx, By, Gs, Gd, Gxy, f00 − f00_calibrated[, Hc, Hs]), Hz.

    With ``ringdowns`` the first-principles model reports what the fit of each decaying
    ring-down reports: the weighted average of the harmonic-balance frequency over its swing
    (:func:`mows.physics.ringdown_average.amplitude_nodes`), from the stop
    (:meth:`Ringdowns.released_swing_rad`). Without, the
    small-amplitude stiffness. The published model has no amplitude (nor ``neighbours``: the
    other probes' fields, first-principles only).
    """
    bx, by, gs, gd, gxy, df00 = params[:6]
    theta0 = np.asarray(theta0_rad, float)
    f00 = f00_hz + df00
    if model == "published":
        sweep = PublishedSweep(
            (bx, by), (gs + gd, gxy, gs - gd), f00, probe.spring_nm_per_rad, probe.moment_am2, probe.lever_m
        )
        shift = sweep.shift_hz(theta0)
        return f00 + shift - f00_hz
    potential = local_potential(params, theta0, probe, neighbours)
    if ringdowns is None:
        return f00 * np.sqrt(potential.stiffness_nm_per_rad() / probe.spring_nm_per_rad) - f00_hz
    if ringdowns.start_swing_rad is not None:
        start = ringdowns.start_swing_about_rad(potential.rest_angle_rad())
    else:
        start = ringdowns.released_swing_rad(potential)
    amplitudes, weights = amplitude_nodes(
        theta0, start, ringdowns.damping_per_s, ringdowns.duration_s, pickup=ringdowns.pickup
    )
    ratios = np.stack([potential.effective_stiffness_nm_per_rad(a) for a in amplitudes.T], axis=-1)
    return f00 * np.sum(weights * np.sqrt(ratios / probe.spring_nm_per_rad), axis=-1) - f00_hz
