"""Rotation-sweep decomposition: in-plane field and gradient from Δf(θ0) (Eqs. 11, 12, S18).

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

Both report f = f00·√(k/kM). A calibrated f00 separates the constant gradient term Gs from
the zero-field frequency; with ``f00_free`` the constant term is absorbed and Gs is not
determined (reported as NaN).

**The field's curvature over the arc.** The stage turns the probe about its magnet's rest
position, and B and G are the field and gradient there. A ring-down swings the magnet along an
arc of the lever, δr ≈ l·(−θ²/2, θ, 0), so the field's second derivatives H_ijk = ∂²B_i/∂x_j∂x_k
add −m·l²·∂²Bx'/∂y'² to the stiffness. Over θ0 that term has two parts. The in-plane harmonic
part of H (H_xxx = −H_xyy = Hc, H_xxy = −H_yyy = Hs: the potential (Hc·Re + Hs·Im)(x + iy)³/6)
gives a 3θ0 harmonic, which ``curvature`` fits: 7 distinct orientations determine it. The trace
part, (H_xxx + H_xyy, H_yxx + H_yyy) = −∂²(Bx, By)/∂z², gives a 1θ0 harmonic that no sweep
tells apart from the field: the B reported is B + (l²/4)·∂²(Bx, By)/∂z² at the magnet's rest
position (docs/multi_probe.md gives its size). Without ``curvature`` the 3θ0 term is left in
the residual, where unequal σ over the sweep leak it into B.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
import itertools
import math

import numpy as np
from scipy.optimize import least_squares

from mows.physics.frequency import PublishedSweep, weak_field_sensitivity_hz_per_t
from mows.physics.pose import probe_axes
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe
from mows.physics.ringdown_average import amplitude_nodes, swing_about_rest_rad

MODELS = ("first_principles", "published")
MAX_HARMONIC = 4
PARAMETER_COUNT = 8  # Bx, By, Gs, Gd, Gxy, Δf00, Hc, Hs
# The rest angles the measured swings are tabulated at: a sweep's static deflections are tens of
# mrad; the swing is smooth in them, so linear interpolation over 5 mrad errs by < 0.1 %.
REST_NODES_RAD = np.linspace(-0.1, 0.1, 41)
F00_STEP_HZ = 1e-4  # the calibrated f00's step for its Jacobian column (the model is smooth in f00)
STOP_STEP_RAD = 1e-4  # the stop's step for its column: 0.006°, within the model's linear range


@dataclasses.dataclass(frozen=True)
class Harmonics:
    """Δf = Σ_k P_k·cos(k·θ0 + φ_k), k = 0 … K, by weighted linear least squares (Eq. 12)."""

    amplitude_hz: np.ndarray
    phase_rad: np.ndarray
    cosine_hz: np.ndarray  # a_k of Σ a_k cos kθ0 + b_k sin kθ0
    sine_hz: np.ndarray  # b_k
    covariance: np.ndarray  # of (a_0, a_1, b_1, …)


def fit_harmonics(theta0_rad, shift_hz, shift_std_hz, max_order: int = 2) -> Harmonics:
    """Harmonic content of a sweep up to ``max_order`` (limited by the number of angles)."""
    theta0 = np.asarray(theta0_rad, float)
    columns = [np.ones_like(theta0)]
    for k in range(1, max_order + 1):
        columns += [np.cos(k * theta0), np.sin(k * theta0)]
    design = np.stack(columns, axis=1) / np.asarray(shift_std_hz, float)[:, None]
    coef, *_ = np.linalg.lstsq(design, np.asarray(shift_hz, float) / shift_std_hz, rcond=None)
    covariance = np.linalg.pinv(design.T @ design)
    a = np.concatenate([[coef[0]], coef[1::2]])
    b = np.concatenate([[0.0], coef[2::2]])
    # P·cos(kθ + φ) = P·cos φ·cos kθ − P·sin φ·sin kθ, so a = P·cos φ and b = −P·sin φ.
    return Harmonics(np.hypot(a, b), np.arctan2(-b, a), a, b, covariance)


class DecompositionStatus(enum.IntEnum):
    """Why a sweep gave no field and gradient; the number is SweepDecomposition's ``status``
    (0 OK, otherwise see ``message``)."""

    OK = 0
    INVALID_INPUT = 1  # unequal lengths, non-finite values, σ ≤ 0
    TOO_FEW_ORIENTATIONS = 2  # fewer distinct θ0 than the model's harmonics need
    NOT_CONVERGED = 3
    NO_DECOMPOSITION = 4  # the sweep ended before one (cancelled, no usable ring-down)


@dataclasses.dataclass
class Decomposition:
    """In-plane field and gradient of one sweep, SI units; NaN unless ``ok``."""

    model: str
    status: DecompositionStatus
    message: str
    field_t: np.ndarray = dataclasses.field(default_factory=lambda: np.full(2, np.nan))
    field_covariance_t2: np.ndarray = dataclasses.field(default_factory=lambda: np.full((2, 2), np.nan))
    gradient_t_per_m: np.ndarray = dataclasses.field(default_factory=lambda: np.full(3, np.nan))  # Gxx, Gxy, Gyy
    gradient_covariance: np.ndarray = dataclasses.field(default_factory=lambda: np.full((3, 3), np.nan))
    f00_hz: float = math.nan
    f00_free: bool = False
    harmonics: Harmonics | None = None
    chi2_dof: float = math.nan
    rms_residual_hz: float = math.nan
    residual_hz: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(0))
    # Bx, By, Gs, Gd, Gxy, Δf00, Hc, Hs (the field's in-plane 3θ0 curvature, T/m², 0 unless fitted)
    parameters: np.ndarray = dataclasses.field(default_factory=lambda: np.full(PARAMETER_COUNT, np.nan))
    # σ of (Bx, By, Gxx, Gxy, Gyy) from the errors shared by every ring-down (the calibrated f00,
    # the stop): their part of the covariance, which no number of ring-downs reduces
    shared_std: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(5))

    @property
    def ok(self) -> bool:
        return self.status is DecompositionStatus.OK

    def _chi2_text(self) -> str:
        """χ²/dof, or why there is none: as many free coefficients as orientations fit exactly."""
        if math.isfinite(self.chi2_dof):
            return f"χ²/dof = {self.chi2_dof:.2f}"
        return "χ²/dof not determined (0 degrees of freedom: as many orientations as free coefficients)"

    def report(self) -> str:
        if not self.ok:
            return f"sweep decomposition ({self.model}): {self.status.name}: {self.message}"
        sb = np.sqrt(np.diag(self.field_covariance_t2))
        sg = np.sqrt(np.diag(self.gradient_covariance))
        bx, by = self.field_t * 1e6
        gxx, gxy, gyy = self.gradient_t_per_m * 1e3
        return (
            f"{self.model}: B = ({bx:.3f} ± {sb[0] * 1e6:.3f}, {by:.3f} ± {sb[1] * 1e6:.3f}) µT, "
            f"|B| = {math.hypot(bx, by):.3f} µT at {math.degrees(math.atan2(by, bx)):.1f}°; "
            f"G = (xx {gxx:.3f} ± {sg[0] * 1e3:.3f}, xy {gxy:.3f} ± {sg[1] * 1e3:.3f}, "
            f"yy {gyy:.3f} ± {sg[2] * 1e3:.3f}) mT/m; {self._chi2_text()}, "
            f"rms residual {self.rms_residual_hz * 1e3:.3f} mHz"
        )


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
    # (:func:`decompose` carries it into the covariance); 0 for a stop taken as exact.
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


def decompose(
    theta0_rad,
    shift_hz,
    shift_std_hz,
    probe: Probe,
    f00_hz: float,
    model: str = "first_principles",
    f00_free: bool = False,
    ringdowns: Ringdowns | None = None,
    start=None,
    f00_std_hz: float = 0.0,
    neighbours: NeighbourFields | None = None,
    curvature: bool = False,
) -> Decomposition:
    """Field and gradient from a rotation sweep by weighted nonlinear least squares.

    Parameters
    ----------
    theta0_rad, shift_hz, shift_std_hz : the measured Δf = f − f00 and its σ at each θ0.
    probe : probe constants (m, kM, l; J and δ enter the first-principles stiffness only
        through k/kM).
    f00_hz : calibrated zero-field frequency that ``shift_hz`` refers to.
    model : ``first_principles`` (default) or ``published``.
    f00_free : fit the zero-field frequency too; Gs is then not determined.
    ringdowns : how the ring-downs were recorded (:class:`Ringdowns`), for the first-principles
        model. The cantilever is not a linear spring: at the 24° a ring-down starts from, the
        field spring is ~1 % and the lever's gradient springs ~4 % weaker than at small
        amplitude (harmonic balance). None: small amplitude.
    start : parameters to start from (Bx, By, Gs, Gd, Gxy, Δf00); default: from the harmonics.
    f00_std_hz : standard uncertainty of the calibrated f00. One error shared by every ring-down
        (``shift_std_hz`` must then be the fits' own σ, without it): it moves the parameters by
        ∂p/∂f00·δ, added to their covariance as σ²·(∂p/∂f00)(∂p/∂f00)ᵀ (mostly Gs: the constant
        term). Not with ``f00_free``, where f00 is fitted.
    neighbours : the other probes' fields at this probe in a sweep of several
        (:class:`NeighbourFields`), part of the first-principles model; the field and gradient
        returned are then the external ones, without them.
    curvature : fit the field's in-plane 3θ0 curvature (Hc, Hs; module docstring), first-principles
        model only; needs 7 distinct orientations.

    The covariance is scaled by χ²/dof when that exceeds 1, as lmfit does: a model that does
    not fit does not get to claim the measurement errors' precision.
    """
    theta0 = np.asarray(theta0_rad, float)
    shift = np.asarray(shift_hz, float)
    std = np.asarray(shift_std_hz, float)
    if model not in MODELS:
        raise ValueError(f"model = {model!r}; use one of {MODELS}")
    if curvature and model != "first_principles":
        raise ValueError(f"curvature needs the first_principles model, not {model!r}")
    status, problem = _check(theta0, shift, std, f00_free, curvature)
    if status is not DecompositionStatus.OK:
        return Decomposition(model, status, problem, f00_free=f00_free)
    harmonics = fit_harmonics(theta0, shift, std, min(MAX_HARMONIC, _distinct_angles(theta0) // 2 - 1 or 1))
    free = np.array([True, True, not f00_free, True, True, f00_free, curvature, curvature])
    start = _start(harmonics, probe, f00_hz, model) if start is None else np.array(start, float)
    start = np.r_[start, np.zeros(PARAMETER_COUNT - start.size)]
    if f00_free:
        start[2] = 0.0  # Gs is absorbed by f00 and stays out of the fit

    def residual_of(params):
        return (model_shift_hz(params, theta0, probe, f00_hz, model, ringdowns, neighbours) - shift) / std

    def residual(x):
        params = start.copy()
        params[free] = x
        return residual_of(params)

    if not np.all(np.isfinite(residual(start[free]))):  # scipy's own words would be its, not the sweep's
        return Decomposition(
            model,
            DecompositionStatus.INVALID_INPUT,
            "the model gives no finite frequency shift at the sweep's starting field and gradient "
            "(a field beyond what the probe's potential describes?)",
            f00_free=f00_free,
        )
    scale = np.array([1e-6, 1e-6, 1e-3, 1e-3, 1e-3, 1e-3, 1.0, 1.0])[free]
    result = least_squares(residual, start[free], x_scale=scale, method="lm", xtol=1e-12, ftol=1e-12)
    params = start.copy()
    params[free] = result.x
    # A calibrated f00 off by δ moves every residual as the Δf00 parameter does (model_shift_hz):
    # its column of the Jacobian, held fixed in the fit, carries f00's σ into the parameters.
    shared: list[tuple[np.ndarray, float]] = []
    if not f00_free and f00_std_hz > 0.0:
        step = np.eye(PARAMETER_COUNT)[5] * F00_STEP_HZ
        f00_column = (residual_of(params + step) - residual_of(params - step)) / (2.0 * F00_STEP_HZ)
        shared.append((f00_column, float(f00_std_hz)))
    if model == "first_principles" and ringdowns is not None and _released_with_std(ringdowns):
        stop_column = _stop_column(params, theta0, shift, std, probe, f00_hz, ringdowns, neighbours)
        shared.append((stop_column, ringdowns.stop_std_rad))
    decomposition = _summarise(model, result, params, free, shift, std, f00_hz, f00_free, harmonics, shared)
    decomposition.parameters = params
    return decomposition


def _released_with_std(ringdowns: Ringdowns) -> bool:
    """Whether the ring-downs start from the stop and its σ is given."""
    return ringdowns.start_swing_rad is None and ringdowns.stop_std_rad > 0.0


def _stop_column(params, theta0, shift, std, probe, f00_hz, ringdowns: Ringdowns, neighbours) -> np.ndarray:
    """∂(residual)/∂stop at ``params``: the stop moved by ±STOP_STEP_RAD through the model's
    own amplitude-dependent springs and start swings."""

    def residual_at(stop_rad: float) -> np.ndarray:
        moved = dataclasses.replace(ringdowns, stop_amplitude_rad=stop_rad)
        return (model_shift_hz(params, theta0, probe, f00_hz, "first_principles", moved, neighbours) - shift) / std

    stop = ringdowns.stop_amplitude_rad
    return (residual_at(stop + STOP_STEP_RAD) - residual_at(stop - STOP_STEP_RAD)) / (2.0 * STOP_STEP_RAD)


def _distinct_angles(theta0) -> int:
    return np.unique(np.round(np.mod(theta0, 2 * np.pi), 6)).size


def unknown_count(f00_free: bool = False, curvature: bool = False) -> int:
    """The decomposition's unknowns (Bx, By, Gs, Gd, Gxy, Δf00 when f00 is free, Hc and Hs with
    the curvature): the field's 1θ0 pair, the gradient's 2θ0 pair and the constant, 5; one more
    with f00 free, two more for the curvature's 3θ0 pair. A sweep needs as many distinct
    orientations."""
    return 5 + int(f00_free) + 2 * int(curvature)


def orientations_problem(theta0_rad, f00_free: bool = False, curvature: bool = False) -> str:
    """Why a sweep at these orientations cannot be decomposed ('' when it can): the field is the
    1θ0 harmonic, the gradient the 2θ0 one, plus a constant (and f00 when free, and the
    curvature's 3θ0 harmonic when fitted)."""
    distinct = _distinct_angles(np.asarray(theta0_rad, float))
    needed = unknown_count(f00_free, curvature)
    if distinct < needed:
        extra = (" and f00" if f00_free else "") + (" and the curvature (3θ0)" if curvature else "")
        return (
            f"{distinct} distinct orientations cannot separate field (1θ0) from gradient "
            f"(2θ0){extra}: need at least {needed}"
        )
    return ""


def _check(theta0, shift, std, f00_free, curvature) -> tuple[DecompositionStatus, str]:
    if not (theta0.shape == shift.shape == std.shape and theta0.ndim == 1):
        return DecompositionStatus.INVALID_INPUT, (
            f"theta0, shift and std must be equal-length 1-D arrays, got {theta0.shape}, {shift.shape}, {std.shape}"
        )
    if not (np.all(np.isfinite(theta0)) and np.all(np.isfinite(shift)) and np.all(np.isfinite(std))):
        return DecompositionStatus.INVALID_INPUT, "non-finite angle, shift or uncertainty in the sweep"
    if np.any(std <= 0):
        return DecompositionStatus.INVALID_INPUT, "every shift needs a positive standard uncertainty"
    if problem := orientations_problem(theta0, f00_free, curvature):
        return DecompositionStatus.TOO_FEW_ORIENTATIONS, problem
    return DecompositionStatus.OK, ""


def _start(harmonics: Harmonics, probe: Probe, f00_hz: float, model: str) -> np.ndarray:
    """Starting point from the first-order harmonics (Eq. 11 with the factor f00)."""
    beta0 = weak_field_sensitivity_hz_per_t(f00_hz, probe.spring_nm_per_rad, probe.moment_am2)
    gamma0 = beta0 * probe.lever_m
    a, b = harmonics.cosine_hz, harmonics.sine_hz
    second = 3.0 if model == "first_principles" else 1.0
    constant = -1.0 if model == "first_principles" else 1.0
    a2, b2 = (a[2], b[2]) if a.size > 2 else (0.0, 0.0)
    return np.array(
        [a[1] / beta0, b[1] / beta0, constant * a[0] / gamma0, a2 / (second * gamma0), b2 / (second * gamma0), 0.0]
    )


def _summarise(model, result, params, free, shift, std, f00_hz, f00_free, harmonics, shared) -> Decomposition:
    """The decomposition of the fit ``result``; ``shared``: (Jacobian column, σ) of each error
    common to every ring-down (the calibrated f00, the stop), added to the covariance."""
    dof = shift.size - int(free.sum())
    chi2_dof = float(result.fun @ result.fun) / dof if dof > 0 else math.nan
    jac = result.jac
    normal_inverse = np.linalg.pinv(jac.T @ jac)
    cov_free = normal_inverse * max(1.0, chi2_dof if math.isfinite(chi2_dof) else 1.0)
    shared_free = np.zeros_like(cov_free)
    for column, shared_std in shared:
        sensitivity = -normal_inverse @ jac.T @ column  # ∂(free parameters)/∂(the shared quantity)
        shared_free = shared_free + shared_std**2 * np.outer(sensitivity, sensitivity)
    cov, shared_cov = np.full((2, PARAMETER_COUNT, PARAMETER_COUNT), np.nan)
    cov[np.ix_(free, free)] = cov_free + shared_free
    shared_cov[np.ix_(free, free)] = shared_free
    bx, by, gs, gd, gxy, df00 = params[:6]
    g_cov = _gradient_covariance(cov)
    shared_std = np.sqrt(np.r_[np.diag(np.nan_to_num(shared_cov[:2, :2])), np.diag(_gradient_covariance(shared_cov))])
    gradient = np.array([gs + gd, gxy, gs - gd])
    if f00_free:  # only (Gxx − Gyy)/2 and Gxy are determined; Gxx and Gyy alone are not
        gradient[[0, 2]] = np.nan
        g_cov[[0, 2], :] = g_cov[:, [0, 2]] = np.nan
    residual = result.fun * std
    return Decomposition(
        model=model,
        status=DecompositionStatus.OK if result.success else DecompositionStatus.NOT_CONVERGED,
        message="" if result.success else f"the fit did not converge in {result.nfev} model evaluations",
        field_t=np.array([bx, by]),
        field_covariance_t2=cov[:2, :2],
        gradient_t_per_m=gradient,
        gradient_covariance=g_cov,
        f00_hz=f00_hz + df00,
        f00_free=f00_free,
        harmonics=harmonics,
        chi2_dof=chi2_dof,
        rms_residual_hz=float(np.sqrt(np.mean(residual**2))),
        residual_hz=residual,
        shared_std=shared_std,
    )


def _gradient_covariance(cov: np.ndarray) -> np.ndarray:
    """Of (Gxx, Gxy, Gyy) = (Gs + Gd, Gxy, Gs − Gd), a linear map of (Gs, Gd, Gxy); a parameter
    held fixed (NaN) has no variance."""
    to_xy = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, -1.0, 0.0]])
    return to_xy @ np.nan_to_num(cov[2:5, 2:5]) @ to_xy.T
