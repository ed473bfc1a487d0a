"""Rotation-sweep decomposition: in-plane field and gradient from Δf(θ0) (Eqs. 11, 12, S18).

A weighted nonlinear least-squares fit of the sweep's model (:mod:`mows.sweep.shift_model`:
``published`` or ``first_principles``, with the field's in-plane curvature when asked). A
calibrated f00 separates the constant gradient term Gs from the zero-field frequency; with
``f00_free`` the constant term is absorbed and Gs is not determined (reported as NaN). The
errors every ring-down of a sweep shares (the calibrated f00, the stop) are carried into the
covariance, and reported apart as the part no number of ring-downs reduces. A sweep needs as
many distinct orientations as the fit has unknowns (:func:`orientations_problem`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from scipy.optimize import least_squares

from mows.physics.frequency import weak_field_sensitivity_hz_per_t
from mows.physics.probe import Probe
from mows.sweep.decomposition import Decomposition, DecompositionStatus, Harmonics, fit_harmonics
from mows.sweep.shift_model import MODELS, PARAMETER_COUNT, NeighbourFields, Ringdowns, model_shift_hz

MAX_HARMONIC = 4
F00_STEP_HZ = 1e-4  # the calibrated f00's step for its Jacobian column (the model is smooth in f00)
STOP_STEP_RAD = 1e-4  # the stop's step for its column: 0.006°, within the model's linear range


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
    curvature : fit the field's in-plane 3θ0 curvature (Hc, Hs; :mod:`mows.sweep.shift_model`), first-principles
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
