"""Rotation-sweep decomposition: in-plane field and gradient from Δf(θ0) (Eqs. 11, 12, S18).

Turning the probe through θ0 changes which field and gradient components it feels. With the
in-plane field B = (Bx, By) and gradient G (G_ij = ∂B_i/∂x_j; Gs = (Gxx + Gyy)/2,
Gd = (Gxx − Gyy)/2, Gxy), the probe axis x' = (cos θ0, sin θ0) sees

    Bx' = Bx·cos θ0 + By·sin θ0,
    Gx'x' = Gs + Gd·cos 2θ0 + Gxy·sin 2θ0,    Gy'y' = Gs − Gd·cos 2θ0 − Gxy·sin 2θ0.

Two models are offered:

``published``   k = kM + m·Bx' + l·m·Gx'x' in Eq. 6 (the paper's Eqs. 11-12 are its first
                order, with the factor f00 restored, PHYSICS.md §3);
``first_principles``  k = U''(θs) of the full potential (PHYSICS.md §4) in the local field
                B + G·δr: exact rest angle (static deflection by By'), the lever's transverse
                gradient term. To first order m·l·(Gx'x' − 2Gy'y') = m·l·(−Gs + 3·(Gd·cos 2θ0
                + Gxy·sin 2θ0)): the 2θ0 harmonic is three times the published one, and the
                constant term has the opposite sign.

Both report f = f00·√(k/kM). A calibrated f00 separates the constant gradient term Gs from
the zero-field frequency; with ``f00_free`` the constant term is absorbed and Gs is not
determined (reported as NaN).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import least_squares

from mows.physics.frequency import sweep_shift_hz, weak_field_sensitivity_hz_per_t
from mows.physics.pose import probe_axes
from mows.physics.potential import ArcPotential
from mows.physics.probe import Probe
from mows.physics.ringdown_average import amplitude_nodes

MODELS = ("first_principles", "published")
MAX_HARMONIC = 4


@dataclasses.dataclass(frozen=True)
class Harmonics:
    """Δf = Σ_k P_k·cos(k·θ0 + φ_k), k = 0 … K, by weighted linear least squares (Eq. 12)."""

    amplitude_hz: np.ndarray
    phase_rad: np.ndarray
    cosine_hz: np.ndarray        # a_k of Σ a_k cos kθ0 + b_k sin kθ0
    sine_hz: np.ndarray          # b_k
    covariance: np.ndarray       # of (a_0, a_1, b_1, …)


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


@dataclasses.dataclass
class Decomposition:
    """In-plane field and gradient of one sweep, SI units; NaN unless ``ok``."""

    model: str
    ok: bool
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
    parameters: np.ndarray = dataclasses.field(default_factory=lambda: np.full(6, np.nan))  # Bx, By, Gs, Gd, Gxy, Δf00

    def report(self) -> str:
        if not self.ok:
            return f"sweep decomposition ({self.model}): {self.message}"
        sb = np.sqrt(np.diag(self.field_covariance_t2))
        sg = np.sqrt(np.diag(self.gradient_covariance))
        bx, by = self.field_t * 1e6
        gxx, gxy, gyy = self.gradient_t_per_m * 1e3
        return (f"{self.model}: B = ({bx:.3f} ± {sb[0] * 1e6:.3f}, {by:.3f} ± {sb[1] * 1e6:.3f}) µT, "
                f"|B| = {math.hypot(bx, by):.3f} µT at {math.degrees(math.atan2(by, bx)):.1f}°; "
                f"G = (xx {gxx:.3f} ± {sg[0] * 1e3:.3f}, xy {gxy:.3f} ± {sg[1] * 1e3:.3f}, "
                f"yy {gyy:.3f} ± {sg[2] * 1e3:.3f}) mT/m; χ²/dof = {self.chi2_dof:.2f}, "
                f"rms residual {self.rms_residual_hz * 1e3:.3f} mHz")


@dataclasses.dataclass(frozen=True)
class Ringdowns:
    """How a sweep's ring-downs were recorded, for the amplitude-dependent springs.

    Every ring-down starts from the housing stop: at ``stop_amplitude_rad`` from the lever's
    undeflected position, so its swing about the rest angle θs (turned by the perpendicular
    field, PHYSICS.md §5.3) is stop − |θs|, which the model computes from its own potential.
    ``damping_per_s`` and ``duration_s`` (per point) give the averaging of a constant-frequency
    fit over the decaying swing (:mod:`mows.physics.ringdown_average`).
    """

    stop_amplitude_rad: float
    damping_per_s: np.ndarray
    duration_s: np.ndarray


def local_potential(params, theta0_rad, probe: Probe) -> ArcPotential:
    """The potential of each point for params (Bx, By, Gs, Gd, Gxy, …): the field and gradient
    turned into the probe frame (Gzz = −(Gxx + Gyy) by ∇·B = 0)."""
    bx, by, gs, gd, gxy = params[:5]
    theta0 = np.asarray(theta0_rad, float)
    rotation = probe_axes(theta0)
    field = rotation @ np.array([bx, by, 0.0])
    gxx, gyy = gs + gd, gs - gd
    global_gradient = np.array([[gxx, gxy, 0.0], [gxy, gyy, 0.0], [0.0, 0.0, -(gxx + gyy)]])
    gradient = rotation @ global_gradient @ np.swapaxes(rotation, -1, -2)
    return ArcPotential.from_local_field(probe, field, gradient)


def model_shift_hz(params, theta0_rad, probe: Probe, f00_hz: float, model: str, ringdowns: Ringdowns | None = None):
    """Δf(θ0) for params (Bx, By, Gs, Gd, Gxy, f00 − f00_calibrated), Hz.

    With ``ringdowns`` the first-principles model reports what the fit of each decaying
    ring-down reports: the weighted average of the harmonic-balance frequency over its swing
    (:func:`mows.physics.ringdown_average.amplitude_nodes`), from stop − |θs|. Without, the
    small-amplitude stiffness. The published model has no amplitude.
    """
    bx, by, gs, gd, gxy, df00 = params
    theta0 = np.asarray(theta0_rad, float)
    f00 = f00_hz + df00
    if model == "published":
        shift = sweep_shift_hz(theta0, (bx, by), (gs + gd, gxy, gs - gd), f00, probe.spring_nm_per_rad,
                               probe.moment_am2, probe.lever_m)
        return f00 + shift - f00_hz
    potential = local_potential(params, theta0, probe)
    if ringdowns is None:
        return f00 * np.sqrt(potential.stiffness_nm_per_rad() / probe.spring_nm_per_rad) - f00_hz
    start = ringdowns.stop_amplitude_rad - np.abs(np.nan_to_num(potential.rest_angle_rad()))
    amplitudes, weights = amplitude_nodes(theta0, start, ringdowns.damping_per_s, ringdowns.duration_s)
    ratios = np.stack([potential.effective_stiffness_nm_per_rad(a) for a in amplitudes.T], axis=-1)
    return f00 * np.sum(weights * np.sqrt(ratios / probe.spring_nm_per_rad), axis=-1) - f00_hz


def decompose(theta0_rad, shift_hz, shift_std_hz, probe: Probe, f00_hz: float, model: str = "first_principles",
              f00_free: bool = False, ringdowns: Ringdowns | None = None, start=None) -> Decomposition:
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
        amplitude (first-harmonic balance). None: small amplitude.
    start : parameters to start from (Bx, By, Gs, Gd, Gxy, Δf00); default: from the harmonics.

    The covariance is scaled by χ²/dof when that exceeds 1, as lmfit does: a model that does
    not fit does not get to claim the measurement errors' precision.
    """
    theta0 = np.asarray(theta0_rad, float)
    shift = np.asarray(shift_hz, float)
    std = np.asarray(shift_std_hz, float)
    if model not in MODELS:
        raise ValueError(f"model = {model!r}; use one of {MODELS}")
    problem = _check(theta0, shift, std, f00_free)
    if problem:
        return Decomposition(model, False, problem, f00_free=f00_free)
    harmonics = fit_harmonics(theta0, shift, std, min(MAX_HARMONIC, _distinct_angles(theta0) // 2 - 1 or 1))
    free = np.array([True, True, not f00_free, True, True, f00_free])
    start = _start(harmonics, probe, f00_hz, model) if start is None else np.array(start, float)
    if f00_free:
        start[2] = 0.0        # Gs is absorbed by f00 and stays out of the fit

    def residual(x):
        params = start.copy()
        params[free] = x
        return (model_shift_hz(params, theta0, probe, f00_hz, model, ringdowns) - shift) / std

    scale = np.array([1e-6, 1e-6, 1e-3, 1e-3, 1e-3, 1e-3])[free]
    result = least_squares(residual, start[free], x_scale=scale, method="lm", xtol=1e-12, ftol=1e-12)
    params = start.copy()
    params[free] = result.x
    decomposition = _summarise(model, result, params, free, shift, std, f00_hz, f00_free, harmonics)
    decomposition.parameters = params
    return decomposition


def _distinct_angles(theta0) -> int:
    return np.unique(np.round(np.mod(theta0, 2 * np.pi), 6)).size


def _check(theta0, shift, std, f00_free) -> str:
    if not (theta0.shape == shift.shape == std.shape and theta0.ndim == 1):
        return f"theta0, shift and std must be equal-length 1-D arrays, got {theta0.shape}, {shift.shape}, {std.shape}"
    if not (np.all(np.isfinite(theta0)) and np.all(np.isfinite(shift)) and np.all(np.isfinite(std))):
        return "non-finite angle, shift or uncertainty in the sweep"
    if np.any(std <= 0):
        return "every shift needs a positive standard uncertainty"
    needed = 6 if f00_free else 5
    if _distinct_angles(theta0) < needed:
        return (f"{_distinct_angles(theta0)} distinct orientations cannot separate field (1θ0) from gradient "
                f"(2θ0){' and f00' if f00_free else ''}: need at least {needed}")
    return ""


def _start(harmonics: Harmonics, probe: Probe, f00_hz: float, model: str) -> np.ndarray:
    """Starting point from the first-order harmonics (Eq. 11 with the factor f00)."""
    beta0 = weak_field_sensitivity_hz_per_t(f00_hz, probe.spring_nm_per_rad, probe.moment_am2)
    gamma0 = beta0 * probe.lever_m
    a, b = harmonics.cosine_hz, harmonics.sine_hz
    second = 3.0 if model == "first_principles" else 1.0
    constant = -1.0 if model == "first_principles" else 1.0
    a2, b2 = (a[2], b[2]) if a.size > 2 else (0.0, 0.0)
    return np.array([a[1] / beta0, b[1] / beta0, constant * a[0] / gamma0, a2 / (second * gamma0),
                     b2 / (second * gamma0), 0.0])


def _summarise(model, result, params, free, shift, std, f00_hz, f00_free, harmonics) -> Decomposition:
    dof = shift.size - int(free.sum())
    chi2_dof = float(result.fun @ result.fun) / dof if dof > 0 else math.nan
    jac = result.jac
    cov_free = np.linalg.pinv(jac.T @ jac) * max(1.0, chi2_dof if math.isfinite(chi2_dof) else 1.0)
    cov = np.full((6, 6), np.nan)
    cov[np.ix_(free, free)] = cov_free
    bx, by, gs, gd, gxy, df00 = params
    # (Gxx, Gxy, Gyy) = (Gs + Gd, Gxy, Gs − Gd): a linear map of (Gs, Gd, Gxy).
    to_xy = np.array([[1.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, -1.0, 0.0]])
    g_cov = to_xy @ np.nan_to_num(cov[2:5, 2:5]) @ to_xy.T      # a parameter held fixed has no variance
    gradient = np.array([gs + gd, gxy, gs - gd])
    if f00_free:  # only (Gxx − Gyy)/2 and Gxy are determined; Gxx and Gyy alone are not
        gradient[[0, 2]] = np.nan
        g_cov[[0, 2], :] = g_cov[:, [0, 2]] = np.nan
    residual = result.fun * std
    return Decomposition(
        model=model, ok=bool(result.success), message="" if result.success else result.message,
        field_t=np.array([bx, by]), field_covariance_t2=cov[:2, :2], gradient_t_per_m=gradient,
        gradient_covariance=g_cov, f00_hz=f00_hz + df00, f00_free=f00_free, harmonics=harmonics,
        chi2_dof=chi2_dof, rms_residual_hz=float(np.sqrt(np.mean(residual**2))), residual_hz=residual)


@dataclasses.dataclass(frozen=True)
class SweepPoint:
    """One successful ring-down of a sweep (SI units; t_s on the device clock)."""

    theta0_rad: float
    frequency_hz: float
    frequency_std_hz: float
    shift_hz: float
    shift_std_hz: float
    amplitude_rad: float
    damping_per_s: float
    duration_s: float
    t_s: float
    amplitude_std_rad: float = math.nan

    @classmethod
    def from_fit(cls, fit, shift_hz: float, shift_std_hz: float, t_s: float = 0.0) -> "SweepPoint":
        """A successful ring-down fit (:class:`mows.estimate.ringdown.RingdownFit`, or a RingdownFit
        message: the fields are the same) with its frequency shift; σ of θmax from the fit's
        covariance (NaN when θmax was held at a bound)."""
        names = list(fit.parameter_names)
        covariance = np.asarray(fit.covariance, float).reshape(len(names), len(names))
        index = names.index("amplitude_rad") if "amplitude_rad" in names else None
        amplitude_std = math.sqrt(covariance[index, index]) if index is not None else math.nan
        return cls(fit.theta0_rad, fit.frequency_hz, fit.frequency_std_hz, shift_hz, shift_std_hz, fit.amplitude_rad,
                   fit.damping_per_s, fit.duration_s, t_s, amplitude_std)


@dataclasses.dataclass
class SweepRecord:
    """The ring-downs of one rotation sweep, collected as they arrive."""

    points: list = dataclasses.field(default_factory=list)
    failed: int = 0

    def add(self, point: SweepPoint) -> None:
        self.points.append(point)

    def _column(self, name: str) -> np.ndarray:
        return np.array([getattr(p, name) for p in self.points], float)

    def at_angle(self, theta0_rad: float) -> tuple[float, float, int]:
        """Inverse-variance weighted mean shift at one orientation, its σ, and the count."""
        chosen = [p for p in self.points if abs(p.theta0_rad - theta0_rad) < 1e-9]
        if not chosen:
            return math.nan, math.nan, 0
        weights = np.array([1.0 / p.shift_std_hz**2 for p in chosen])
        shifts = np.array([p.shift_hz for p in chosen])
        return float(weights @ shifts / weights.sum()), float(1.0 / math.sqrt(weights.sum())), len(chosen)

    def stop_amplitude_rad(self, rest_angles_rad=None) -> float:
        """The swing a ring-down starts with when the probe rests undeflected: the
        inverse-variance weighted mean of the fits' θmax + |θs| (θs: each point's rest angle,
        0 when not given).

        Every ring-down starts from the housing stop, and the perpendicular excitation scheme
        drives every orientation alike; a single fit's θmax, though, is poorly determined near
        θ0 = 180° (and held at a bound when unidentifiable), so the sweep's pooled value is the
        better input to the amplitude-dependent springs. The median when no σ is known.
        """
        amplitude = self._column("amplitude_rad")
        if rest_angles_rad is not None:
            amplitude = amplitude + np.abs(np.asarray(rest_angles_rad, float))
        std = self._column("amplitude_std_rad")
        usable = np.isfinite(std) & (std > 0)
        if not usable.any():
            return float(np.median(amplitude))
        weights = 1.0 / std[usable] ** 2
        return float(weights @ amplitude[usable] / weights.sum())

    def decompose(self, probe: Probe, f00_hz: float, model: str = "first_principles",
                  f00_free: bool = False) -> Decomposition:
        """:func:`decompose` of every ring-down (not of per-angle means, so χ² keeps its dof).

        The first-principles model needs the swing each ring-down starts with, stop − |θs|, and
        θs depends on the field it is fitting: a first pass with θs = 0 gives the field, its rest
        angles give the pooled stop amplitude, and a second pass fits with both.
        """
        theta0 = self._column("theta0_rad")
        arrays = dict(theta0_rad=theta0, shift_hz=self._column("shift_hz"), shift_std_hz=self._column("shift_std_hz"),
                      probe=probe, f00_hz=f00_hz, model=model, f00_free=f00_free)
        if model != "first_principles":
            return decompose(**arrays)

        def ringdowns(stop):
            return Ringdowns(stop, self._column("damping_per_s"), self._column("duration_s"))

        first = decompose(**arrays, ringdowns=ringdowns(self.stop_amplitude_rad()))
        if not first.ok:
            return first
        rest = np.nan_to_num(local_potential(first.parameters, theta0, probe).rest_angle_rad())
        return decompose(**arrays, ringdowns=ringdowns(self.stop_amplitude_rad(rest)), start=first.parameters)

    def start_amplitudes_rad(self, decomposition: Decomposition, probe: Probe) -> np.ndarray:
        """Each ring-down's start swing, stop − |θs|, at the decomposition's field and gradient."""
        theta0 = self._column("theta0_rad")
        rest = np.abs(np.nan_to_num(local_potential(decomposition.parameters, theta0, probe).rest_angle_rad()))
        return self.stop_amplitude_rad(rest) - rest

    def table_columns(self, start_amplitudes_rad=None) -> dict:
        """Columns of a model-lab measurement table (docs/model_lab.md). ``amplitude_deg`` is each
        ring-down's start swing: ``start_amplitudes_rad`` (e.g. :meth:`start_amplitudes_rad` of
        a decomposition), else the pooled :meth:`stop_amplitude_rad`."""
        t = self._column("t_s")
        start = (np.full(len(self.points), self.stop_amplitude_rad()) if start_amplitudes_rad is None
                 else np.asarray(start_amplitudes_rad, float))
        return {"theta0_deg": np.degrees(self._column("theta0_rad")), "f_hz": self._column("frequency_hz"),
                "f_std_hz": self._column("frequency_std_hz"), "t_s": t - (t.min() if t.size else 0.0),
                "amplitude_deg": np.degrees(start),
                "damping_per_s": self._column("damping_per_s"), "duration_s": self._column("duration_s")}
