"""A probe calibration's reported constants from the fitted parameters (paper Eqs. 9, 10, S1):
kM = f00·m/(2β0), J from the damped relation J = kM/((2π·f00)² + δ²), l = √(J/a), and with
gradient points the lever from the gradient response γ = β0·l·(1 − 2·Gy'y'/Gx'x')
(docs/physics.md §6.1), all with their covariance by the delta method over the fit's
parameters and the ring-downs' mean damping; the two levers compared in a note.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from mows.estimate.calibration.constants import (
    CalibrationError,
    CalibrationPoint,
    KnownConstants,
    ProbeCalibration,
    Wiring,
)
from mows.estimate.calibration.predicted import inertia_from
from mows.physics.probe import lever_from_inertia

# (f00 Hz, β0 Hz/T, environment field (3,) T, lever m, start swing rad) of the fit's parameters x
Unpacked = tuple[float, float, np.ndarray, float, float]


@dataclasses.dataclass(frozen=True)
class Fitted:
    """The fit's parameters x (fit units) with their covariance, how they unpack into (f00, β0,
    environment field, lever, start swing), and the ring-downs' mean damping δ with its variance."""

    x: np.ndarray
    cov_x: np.ndarray
    unpack: Callable[[np.ndarray], Unpacked]
    damping: float
    damping_var: float
    unit_axis: np.ndarray  # the homogeneous supply's field direction
    fit_environment: bool
    fit_lever: bool


def derive(
    fitted: Fitted,
    wirings: Mapping[str, Wiring],
    gradient_points: Sequence[CalibrationPoint],
    known: KnownConstants,
    chi2_dof: float,
    n_points: int,
    notes: tuple[str, ...],
) -> ProbeCalibration:
    """The reported constants and their covariance by the delta method over (x, δ)."""
    x, cov_x, unpack, unit_axis = fitted.x, fitted.cov_x, fitted.unpack, fitted.unit_axis
    fit_environment, fit_lever = fitted.fit_environment, fitted.fit_lever
    names = [
        "f00_hz",
        "beta0_hz_per_t",
        "spring_nm_per_rad",
        "inertia_kgm2",
        "lever_m",
        "damping_per_s",
        "theta_stop_rad",  # the housing stop the ring-downs are released at
    ]
    names += ["environment_field_along_supply_t"] * fit_environment
    gradient_factor = _gradient_factor(wirings, gradient_points) if fit_lever else None
    names += ["gradient_lever_m", "gamma_hz_m_per_t"] * fit_lever

    def constants(z: np.ndarray) -> np.ndarray:
        f00, beta0, environment, lever, stop = unpack(z[:-1])
        delta = z[-1]
        spring = f00 * known.moment_am2 / (2.0 * beta0)
        inertia = inertia_from(f00, spring, delta)
        values = [f00, beta0, spring, inertia, lever_from_inertia(inertia, known.magnet_mass_kg), delta, stop]
        values += [float(environment @ unit_axis)] * fit_environment
        if fit_lever:
            assert gradient_factor is not None  # computed whenever the lever is fitted
            values += [lever, beta0 * lever * gradient_factor]
        return np.array(values)

    z = np.append(x, fitted.damping)
    cov_z = np.zeros((len(z), len(z)))
    cov_z[:-1, :-1], cov_z[-1, -1] = cov_x, fitted.damping_var
    steps = np.maximum(np.abs(z), 1e-12) * 1e-6
    jac = np.stack([(constants(z + e) - constants(z - e)) / (2.0 * s) for e, s in zip(np.diag(steps), steps)], -1)
    values = constants(z)
    covariance = jac @ cov_z @ jac.T
    if fit_lever:
        lever, lever_j = values[names.index("gradient_lever_m")], values[names.index("lever_m")]
        i, j = names.index("gradient_lever_m"), names.index("lever_m")
        sigma = math.sqrt(max(covariance[i, i] + covariance[j, j] - 2.0 * covariance[i, j], 0.0))
        notes = notes + (
            f"lever check: l from the gradient {lever * 1e3:.4f} mm against l = √(J/a) "
            f"{lever_j * 1e3:.4f} mm, {(lever - lever_j) / sigma:+.2f} σ apart",
        )
    return ProbeCalibration(tuple(names), values, covariance, chi2_dof, n_points, known, notes)


def _gradient_factor(wirings: Mapping[str, Wiring], gradient_points: Sequence[CalibrationPoint]) -> float:
    """γ/(β0·l) of the gradient wiring at θ0 = 0: 1 − 2·Gy'y'/Gx'x' (docs/physics.md §6.1: k gains
    m·l·(Gx'x' − 2·Gy'y')); 2 for an anti-Helmholtz pair along x."""
    gradient = np.asarray(wirings[gradient_points[0].wiring].gradient_per_a_t_per_m, float)
    if gradient[0, 0] == 0.0:
        raise CalibrationError("the gradient wiring has no Gxx at the probe: γ along x undetermined")
    return 1.0 - 2.0 * gradient[1, 1] / gradient[0, 0]
