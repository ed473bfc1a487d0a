"""Calibrating a new probe from ring-downs at known applied fields (paper Fig. 3, Eqs. 9–10).

This module is the fit; what goes in and comes out is :mod:`mows.estimate.calibration.constants`,
the model of one ring-down :mod:`mows.estimate.calibration.predicted`, the constants derived from
the fitted parameters :mod:`mows.estimate.calibration.derived`, and which way each wiring is
connected :mod:`mows.estimate.calibration.polarity`.

The paper steps a Helmholtz pair's current, reads Δf against B, takes the slope β0 and derives
kM = f00·m/(2β0) (Eq. 9 inverted) and J = m/(8π²·β0·f00) (Eq. 10), and l = √(J/a) from the
magnet mass a; the same pair anti-parallel gives the gradient response γ. Here the same
constants come from the **full potential** (:mod:`mows.physics.potential`) rather than Eq. 6:

* every ring-down is modelled as the estimator sees it: the harmonic-balance frequency of
  U(θ) = ½·kM·θ² − m(θ)·B(r(θ)) at the ring-down's decaying amplitude, averaged as a
  constant-frequency fit averages it (:mod:`mows.physics.ringdown_average`). Eq. 6 ignores the
  finite amplitude, which shrinks the field spring by 2·J1(A)/A (2.2 % at the paper's 24°) and
  would bias β0, kM and J by as much;
* the perpendicular field's static deflection and the lever in a gradient (k gains
  m·l·(Gx'x' − 2·Gy'y'), twice the paper's kG in an anti-Helmholtz field) are in U as well;
* J is taken from the damped relation J = kM/((2π·f00)² + δ²) (Eq. S1), δ the ring-downs' mean
  damping; Eq. 10 neglects δ (6.5e-6 relative for the paper's probe).

Parameters fitted by weighted least squares: f00, β0, the ring-downs' start swing at the
switch-off, the environment field along the supply's axis (unless a reference magnetometer gave
it) and, with gradient points, the lever l_γ. A homogeneous sweep cannot tell the start swing
from β0 (both scale the field spring), so the swing is held by a measurement: the median of
the fits' own θmax (or a value given in :class:`KnownConstants`); its uncertainty enters β0's. Each
ring-down's own swing also scatters about that mean (by ~0.12° in the simulator, where the
drive leaves the probe at a random phase of its bounce off the stop): a per-ring-down error of
∂f/∂A·s that grows with the field, its size s estimated from the frequencies' excess scatter
(a variance component) and weighted in, not shared by all ring-downs. The covariance is
(JᵀWJ)⁻¹, the frequencies' part widened by χ²/dof when that still exceeds 1; derived constants
carry it by the delta method, so every constant has an uncertainty and all have correlations.

What the data cannot determine raises :class:`CalibrationError` with the reason: fewer than two
distinct applied fields (β0), fields of one sign only without a reference (f00 and the
environment field along the axis are then interchangeable), no usable ring-down at a supply
current (the fits failed, e.g. saturated sensors). Without gradient points the lever comes from
J and a alone, and the report says that the lever check could not be made.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np
from scipy import optimize

from mows.estimate.calibration.constants import (
    CalibrationError,
    CalibrationPoint,
    KnownConstants,
    ProbeCalibration,
    Wiring,
)
from mows.estimate.calibration.derived import Fitted, Unpacked, derive
from mows.estimate.calibration.polarity import polarity_note, wiring_polarities
from mows.estimate.calibration.predicted import frequencies, rows_of
from mows.physics.ringdown_average import stop_from_swing_rad, stop_median_std_rad

FIELD_UNIT_T = 1e-6  # fit units keep the normal equations well scaled: µT, Hz/mT, mm
BETA_UNIT_HZ_PER_T = 1e3
LEVER_UNIT_M = 1e-3
AMPLITUDE_UNIT_RAD = 1e-3
# Central-difference steps of the Jacobian in those units (f00, β0, swing, environment, lever):
# large against the model's rounding (~1e-9 Hz), small against its curvature.
STEPS = {"f00": 1e-4, "beta0": 1e-5, "swing": 1e-2, "environment": 0.1, "lever": 1e-4}
SCATTER_ITERATIONS = 2  # weights from the scatter, the scatter from the fit: twice settles it
MAX_SCATTER_RAD = math.radians(1.0)  # a start swing scattering more is no drive into the stop
# Where no fit pins the stop: the drive, switched off at a current peak, leaves every ring-down
# at the housing stop, scattered by sd 0.01° (the simulator's first swing + |θs| over 30
# ring-downs at 0 to ±2 A for a 24° stop: 24.03 ± 0.01°, mean ± sd).
STOP_PRIOR_STD_RAD = math.radians(0.01)
SWING_FLOOR_RAD = 1e-6  # fits that agree exactly (synthetic data) still leave a finite weight


Residuals = Callable[[np.ndarray], np.ndarray]


# --- the fit -----------------------------------------------------------------------------------
def calibrate_probe(
    points: Sequence[CalibrationPoint],
    wirings: dict[str, Wiring] | Sequence[Wiring],
    known: KnownConstants,
    field_wiring: str = "helmholtz",
    failed: dict[tuple[float, str], int] | None = None,
    nominal_lever_m: float = 1.9e-3,
    polarity: dict[str, int] | None = None,
) -> ProbeCalibration:
    """Fit the probe's constants to ``points`` (:class:`CalibrationPoint`).

    ``wirings``: :class:`Wiring` by name (or a sequence of them); ``field_wiring`` names the
    homogeneous one (β0); points of any other wiring are gradient points (lever). ``failed``
    counts ring-downs whose fit failed, by supply current and reason, for the notes and the
    saturation check. ``polarity``: +1 or −1 by wiring name, the sign of its current as
    wired; a wiring not given is found from the data (:func:`wiring_polarities`), and a reversed
    one is said in the notes. CalibrationError when the data cannot determine the constants or
    give implausible ones (a unit error).
    """
    wirings = wirings if isinstance(wirings, dict) else {w.name: w for w in wirings}
    usable = [
        p
        for p in points
        # θmax may be NaN ("not determined"): the model starts every ring-down at the stop.
        if all(map(math.isfinite, (p.frequency_hz, p.frequency_std_hz, p.damping_per_s, p.duration_s)))
    ]
    notes = _dropped_notes(points, usable) + _failure_notes(failed or {}, usable)
    polarity = {**wiring_polarities(usable, wirings, known, nominal_lever_m), **(polarity or {})}
    notes += [polarity_note(name, sign) for name, sign in polarity.items() if sign < 0]
    points = [dataclasses.replace(p, supply_current_a=p.supply_current_a * polarity.get(p.wiring, 1)) for p in usable]
    field_points = [p for p in points if p.wiring == field_wiring]
    gradient_points = [p for p in points if p.wiring != field_wiring]
    rows = rows_of(points, wirings, known)
    axis = _field_axis(wirings, field_wiring)
    _check_field_points(field_points, axis, known)
    fit_environment = known.environment_field_t is None
    fit_lever = any(p.supply_current_a != 0.0 for p in gradient_points)
    if not fit_lever:
        notes.append("no gradient points: the lever comes from J and the magnet mass alone, unchecked")
    damping, damping_var = _mean_damping(points)
    swing, swing_std, stop_measured = _housing_stop(points, known)
    if not stop_measured:
        notes.append(
            f"no fit determined θmax: the stop is the nominal {math.degrees(swing):.3f}°, "
            f"± {math.degrees(max(swing_std, known.theta_stop_std_rad)):.3f}° as stated"
        )
    unit_axis = axis / np.linalg.norm(axis)
    fixed_environment = np.zeros(3) if fit_environment else np.asarray(known.environment_field_t, float)

    def unpack(x: np.ndarray) -> Unpacked:
        environment = fixed_environment + (x[3] * FIELD_UNIT_T * unit_axis if fit_environment else 0.0)
        lever = x[-1] * LEVER_UNIT_M if fit_lever else nominal_lever_m
        return x[0], x[1] * BETA_UNIT_HZ_PER_T, environment, lever, x[2] * AMPLITUDE_UNIT_RAD

    def model(x: np.ndarray) -> np.ndarray:
        return frequencies(rows, known, *unpack(x), damping)

    def residuals(x: np.ndarray, sigma_hz: np.ndarray) -> np.ndarray:
        prior = (x[2] * AMPLITUDE_UNIT_RAD - swing) / swing_std
        return np.append((model(x) - rows.frequency_hz) / sigma_hz, prior)

    start = _start(field_points, wirings[field_wiring], known)
    x0 = np.array(
        [start[0], start[1] / BETA_UNIT_HZ_PER_T, known.theta_stop_rad / AMPLITUDE_UNIT_RAD]
        + [0.0] * fit_environment
        + [nominal_lever_m / LEVER_UNIT_M] * fit_lever
    )
    steps = np.array(
        [STEPS[k] for k in ["f00", "beta0", "swing"] + ["environment"] * fit_environment + ["lever"] * fit_lever]
    )
    dof = len(points) + 1 - len(x0)
    if dof <= 0:
        raise CalibrationError(
            f"{len(points)} usable ring-down(s) for {len(x0) - 1} constants leave {dof} degrees of freedom: "
            "nothing would test the fit; add supply currents or orientations"
        )
    result = _least_squares(lambda x: residuals(x, rows.frequency_std_hz), x0, steps)
    scatter_rad = 0.0
    for _ in range(SCATTER_ITERATIONS):
        slope = _swing_slope_hz_per_rad(model, result.x)
        scatter_rad = _swing_scatter_rad(model(result.x) - rows.frequency_hz, rows.frequency_std_hz, slope, dof)
        sigma_hz = np.hypot(rows.frequency_std_hz, slope * scatter_rad)
        result = _least_squares(functools.partial(residuals, sigma_hz=sigma_hz), result.x, steps)
    if scatter_rad > 0.0:
        notes.append(
            f"the ring-downs' start swings scatter by {math.degrees(scatter_rad):.3f}° about their mean "
            "(from the frequencies' scatter beyond the fits' uncertainty): weighted in"
        )
    chi2_dof = float(result.fun @ result.fun / dof) if dof > 0 else math.nan
    # A χ²/dof above 1 widens what the frequencies say, never the start swing's measurement.
    jac = result.jac.copy()
    jac[:-1] /= math.sqrt(max(1.0, chi2_dof if dof > 0 else 1.0))
    cov_x = _covariance(
        jac, ["f00", "β0", "start swing"] + ["environment field"] * fit_environment + ["lever"] * fit_lever
    )
    fitted = Fitted(result.x, cov_x, unpack, damping, damping_var, unit_axis, fit_environment, fit_lever)
    calibration = derive(fitted, wirings, gradient_points, known, chi2_dof, len(points), tuple(notes))
    implausible = calibration.probe().implausible()
    if implausible:
        raise CalibrationError(
            f"implausible constants, probably a unit error (currents in mA? f_hz in kHz?): {'; '.join(implausible)}"
        )
    return dataclasses.replace(calibration, polarity=polarity, stop_measured=stop_measured)


def _dropped_notes(points: Sequence[CalibrationPoint], usable: Sequence[CalibrationPoint]) -> list[str]:
    """One note per ring-down left out for a value that is not a finite number."""
    return [
        f"ring-down {i + 1} ({p.supply_current_a:+.4f} A, θ0 {math.degrees(p.theta0_rad):.1f}°) left out: "
        "its frequency, uncertainty, damping or duration is not a finite number"
        for i, p in enumerate(points)
        if p not in usable
    ]


def _least_squares(residuals: Residuals, x0: np.ndarray, steps: np.ndarray) -> optimize.OptimizeResult:
    if not np.all(np.isfinite(residuals(x0))):  # scipy would say "Residuals are not finite in the initial point"
        raise CalibrationError(
            "the model gives no finite frequency for the data's starting constants: "
            "check the table's units (f_hz in Hz, currents in A) and the supply's field per ampere"
        )
    result = optimize.least_squares(
        residuals, x0, jac=lambda x: _jacobian(residuals, x, steps), method="lm", x_scale="jac"
    )
    if not result.success or not np.all(np.isfinite(result.fun)):
        raise CalibrationError(
            f"the fit of the calibration did not converge in {result.nfev} model evaluations: these ring-downs "
            "do not pin the constants down; measure at two orientations 180° apart with supply currents of "
            "both signs on each pair"
        )
    return result


def _housing_stop(points: Sequence[CalibrationPoint], known: KnownConstants) -> tuple[float, float, bool]:
    """The housing stop every ring-down starts from, its standard uncertainty, and whether it
    was measured: as given (``known.measured_stop_rad``), else measured by the fits that
    determined both θmax and the rest offset, θmax grown back by e^(δ·t) to the switch-off plus
    |θs − θ0| (:func:`mows.physics.ringdown_average.stop_from_swing_rad`), their median with its
    standard error (:func:`mows.physics.ringdown_average.stop_median_std_rad`); with too few of
    them the probe's stop ± STOP_PRIOR_STD_RAD, not measured.
    A homogeneous sweep cannot tell the stop from β0: this is what holds it."""
    if known.measured_stop_rad is not None:
        return known.measured_stop_rad, known.measured_stop_std_rad, True
    stops = stop_from_swing_rad(
        [p.amplitude_rad for p in points],
        [p.rest_offset_rad for p in points],
        [p.damping_per_s for p in points],
        [p.start_offset_s for p in points],
    )
    std = stop_median_std_rad(stops)
    if not math.isfinite(std):  # too few fits for a spread
        return known.theta_stop_rad, STOP_PRIOR_STD_RAD, False
    return float(np.nanmedian(stops)), max(std, SWING_FLOOR_RAD), True


def _swing_slope_hz_per_rad(model: Residuals, x: np.ndarray) -> np.ndarray:
    """∂f/∂(start swing) of every ring-down: each depends on its own swing alone."""
    e = np.zeros_like(x)
    e[2] = STEPS["swing"]
    return (model(x + e) - model(x - e)) / (2.0 * STEPS["swing"] * AMPLITUDE_UNIT_RAD)


def _swing_scatter_rad(residual_hz: np.ndarray, std_hz: np.ndarray, slope_hz_per_rad: np.ndarray, dof: int) -> float:
    """The scatter s of the ring-downs' own start swings about their mean: the s ≥ 0 that makes
    Σ r²/(σ² + (∂f/∂A·s)²) = dof (a variance component: the scatter shows in the frequencies
    in proportion to the field term, not at zero field). 0 when the fits' σ explain the
    residuals; at most MAX_SCATTER_RAD (beyond it the excess is not the swing's, and χ²/dof
    widens the uncertainties instead)."""

    def excess(s2: float) -> float:
        return float(np.sum(residual_hz**2 / (std_hz**2 + slope_hz_per_rad**2 * s2))) - dof

    if dof <= 0 or excess(0.0) <= 0.0:
        return 0.0
    if excess(MAX_SCATTER_RAD**2) >= 0.0:
        return MAX_SCATTER_RAD
    return math.sqrt(optimize.brentq(excess, 0.0, MAX_SCATTER_RAD**2, xtol=1e-14, rtol=1e-6))


def _jacobian(residuals: Residuals, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    columns = []
    for k, h in enumerate(steps):
        e = np.zeros_like(x)
        e[k] = h
        columns.append((residuals(x + e) - residuals(x - e)) / (2.0 * h))
    return np.stack(columns, -1)


def _covariance(jac: np.ndarray, names: list[str]) -> np.ndarray:
    """(JᵀJ)⁻¹; CalibrationError naming the parameters the data leave undetermined."""
    u, s, vt = np.linalg.svd(jac, full_matrices=False)
    if s[-1] < 1e-9 * s[0]:
        weak = [names[i] for i in np.flatnonzero(np.abs(vt[-1]) > 0.3)]
        raise CalibrationError(
            f"the data cannot determine {' and '.join(weak)} (separately): add supply currents or orientations"
        )
    return (vt.T / s**2) @ vt


def _field_axis(wirings: Mapping[str, Wiring], field_wiring: str) -> np.ndarray:
    """The homogeneous wiring's field per ampere at the probe; CalibrationError without one."""
    axis = np.asarray(wirings[field_wiring].field_per_a_t, float) if field_wiring in wirings else np.zeros(3)
    if not np.any(axis):
        raise CalibrationError(
            f"no homogeneous-field wiring {field_wiring!r} with a field at the probe is described: β0 undetermined"
        )
    return axis


def _check_field_points(points: Sequence[CalibrationPoint], axis: np.ndarray, known: KnownConstants) -> None:
    """CalibrationError when the homogeneous sweep cannot determine β0 and f00."""
    along = np.array(
        [p.supply_current_a * (axis[0] * math.cos(p.theta0_rad) + axis[1] * math.sin(p.theta0_rad)) for p in points]
    )
    distinct = np.unique(np.round(along / np.linalg.norm(axis), 6))
    if len(distinct) < 2:
        raise CalibrationError(
            f"too few supply currents: {len(points)} usable ring-downs at {len(distinct)} distinct "
            "field(s) along the probe axis; β0 (hence kM and J) needs at least two"
        )
    if known.environment_field_t is None and not (along.min() < 0.0 < along.max()):
        raise CalibrationError(
            "fields of one sign only along the probe axis: f00 and the environment field along "
            "the supply's axis cannot be told apart; add θ0 = 180° (or negative currents) or "
            "give the environment field from a reference magnetometer"
        )


def _failure_notes(failed: dict[tuple[float, str], int], points: Sequence[CalibrationPoint]) -> list[str]:
    """Notes on failed ring-downs; CalibrationError if a supply current has no usable one."""
    notes, usable = [], {p.supply_current_a for p in points}
    for (current, reason), count in sorted(failed.items()):
        notes.append(f"{count} ring-down fit(s) at {current:+.4f} A failed ({reason}) and were left out")
        if current not in usable:
            raise CalibrationError(
                f"no usable ring-down at the supply current {current:+.4f} A: every fit failed "
                f"({reason}); lower the currents (saturation) or repeat that step"
            )
    return notes


def _mean_damping(points: Sequence[CalibrationPoint]) -> tuple[float, float]:
    """The ring-downs' mean damping and the variance of that mean (from their scatter)."""
    values = np.array([p.damping_per_s for p in points])
    var = float(values.var(ddof=1) / len(values)) if len(values) > 1 else float(values[0] ** 2)
    return float(values.mean()), var


def _start(points: Sequence[CalibrationPoint], wiring: Wiring, known: KnownConstants) -> tuple[float, float]:
    """f00 and β0 from a straight line through f against the applied field along x'."""
    axis = np.asarray(wiring.field_per_a_t, float)
    along = np.array(
        [p.supply_current_a * (axis[0] * math.cos(p.theta0_rad) + axis[1] * math.sin(p.theta0_rad)) for p in points]
    )
    slope, intercept = np.polyfit(along, [p.frequency_hz for p in points], 1)
    return float(intercept), float(slope) if slope > 0 else 3.68e3
