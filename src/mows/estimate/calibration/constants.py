"""What a probe calibration takes and gives (:mod:`mows.estimate.calibration.fit_constants`).

In: the fitted ring-downs at supply currents (:class:`CalibrationPoint`), how each wiring of the
supply makes a field at the probe (:class:`Wiring`) and what is taken as given
(:class:`KnownConstants`). Out: the calibrated constants with their covariance
(:class:`ProbeCalibration`) and the ``calibration`` section of a probe file it writes.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.estimate.ringdown.types import RingdownFit
from mows.physics.field import FieldSource
from mows.physics.probe import DEFAULT_THETA_STOP_STD_RAD, Probe
from mows.physics.schema import Vector


class CalibrationError(ValueError):
    """The data cannot determine a constant; the message says which and why."""


@dataclasses.dataclass(frozen=True)
class Wiring:
    """How the supply's current becomes a field at the magnet's rest position (global frame):
    ``field_per_a_t`` (3,) and ``gradient_per_a_t_per_m`` (3, 3), per ampere."""

    name: str
    field_per_a_t: tuple[float, ...]
    gradient_per_a_t_per_m: tuple[tuple[float, ...], ...] = ((0.0,) * 3,) * 3

    @classmethod
    def from_source(cls, name: str, source_per_a: FieldSource, position_m: Vector = (0.0, 0.0, 0.0)) -> Wiring:
        """The wiring of a field source (its field at 1 A) at ``position_m``."""
        point = np.asarray(position_m, float)
        return cls(
            name,
            tuple(source_per_a.field_t(point).tolist()),
            tuple(map(tuple, source_per_a.gradient_t_per_m(point).tolist())),
        )


@dataclasses.dataclass(frozen=True)
class CalibrationPoint:
    """One fitted ring-down (``mows.estimate.ringdown.RingdownFit``) at a supply current."""

    wiring: str
    supply_current_a: float
    theta0_rad: float
    frequency_hz: float
    frequency_std_hz: float
    amplitude_rad: float
    damping_per_s: float
    duration_s: float
    start_offset_s: float = 0.0  # first fitted sample after the switch-off
    rest_offset_rad: float = math.nan  # the fit's rest offset θs − θ0 (NaN: not determined)

    @classmethod
    def from_fit(cls, fit: RingdownFit, wiring: str, supply_current_a: float) -> CalibrationPoint:
        return cls(
            wiring,
            float(supply_current_a),
            fit.theta0_rad,
            fit.frequency_hz,
            fit.frequency_std_hz,
            fit.amplitude_rad,
            fit.damping_per_s,
            fit.duration_s,
            fit.start_offset_s,
            float(getattr(fit, "rest_offset_rad", math.nan)),
        )


@dataclasses.dataclass(frozen=True)
class KnownConstants:
    """What the calibration takes as given: the magnet's moment and mass (data sheet, scale),
    the housing stop, and optionally the environment field at the probe with the supply at
    zero (a reference magnetometer), global frame, and the housing stop the ring-downs are
    released at with its uncertainty when it was measured apart (None: from the fits' θmax)."""

    moment_am2: float
    magnet_mass_kg: float
    theta_stop_rad: float = math.radians(24.0)
    environment_field_t: tuple[float, ...] | None = None
    measured_stop_rad: float | None = None
    measured_stop_std_rad: float = 0.0
    theta_stop_std_rad: float = DEFAULT_THETA_STOP_STD_RAD  # the nominal stop's stated tolerance

    @classmethod
    def of(cls, probe: Probe, environment_field_t: Vector | None = None) -> KnownConstants:
        return cls(
            probe.moment_am2,
            probe.magnet_mass_kg,
            probe.theta_stop_rad,
            None if environment_field_t is None else tuple(float(b) for b in environment_field_t),
            theta_stop_std_rad=probe.theta_stop_std_rad,
        )


@dataclasses.dataclass(frozen=True)
class ProbeCalibration:
    """The calibrated constants (SI), their covariance and what the data could not say."""

    names: tuple[str, ...]
    values: np.ndarray
    covariance: np.ndarray
    chi2_dof: float
    n_points: int
    known: KnownConstants
    notes: tuple[str, ...] = ()
    polarity: dict[str, int] = dataclasses.field(default_factory=dict)  # wiring → +1 as written, −1 reversed
    stop_measured: bool = True  # False: no fit determined the stop, the nominal one was held

    def value(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def std(self, name: str) -> float:
        i = self.names.index(name)
        return float(math.sqrt(self.covariance[i, i]))

    def correlation(self) -> np.ndarray:
        std = np.sqrt(np.diag(self.covariance))
        with np.errstate(invalid="ignore", divide="ignore"):
            return self.covariance / np.outer(std, std)

    def stop_std_rad(self) -> float:
        """The σ of the stop the probe file carries: the calibration's, where it measured the
        stop; else the nominal stop's stated tolerance, which the fit's prior (the drive's
        scatter about it) would understate."""
        if self.stop_measured:
            return self.std("theta_stop_rad")
        return max(self.std("theta_stop_rad"), self.known.theta_stop_std_rad)

    def probe(self) -> Probe:
        """The calibrated probe (lever from J and the magnet mass), with the stop the ring-downs
        were released at and its σ (:meth:`stop_std_rad`), which every strong-field map rests on."""
        return Probe(
            moment_am2=self.known.moment_am2,
            spring_nm_per_rad=self.value("spring_nm_per_rad"),
            inertia_kgm2=self.value("inertia_kgm2"),
            lever_m=self.value("lever_m"),
            magnet_mass_kg=self.known.magnet_mass_kg,
            damping_per_s=self.value("damping_per_s"),
            theta_stop_rad=self.value("theta_stop_rad"),
            theta_stop_std_rad=self.stop_std_rad(),
        )

    def record(self, date: str, hardware_id: str) -> dict:
        """The ``calibration`` section of a probe file: values with uncertainties, correlations."""
        return {
            "date": date,
            "hardware_id": hardware_id,
            "method": "supply sweep, full potential (mows calibrate)",
            "points": self.n_points,
            "chi2_dof": float(self.chi2_dof),
            "constants": {n: {"value": float(v), "std": self.std(n)} for n, v in zip(self.names, self.values)},
            "correlation": [[round(float(c), 6) for c in row] for row in self.correlation()],
            "notes": list(self.notes),
            "polarity": {name: int(sign) for name, sign in self.polarity.items()},
        }

    def report(self) -> str:
        lines = [f"{n} = {self.value(n):.6g} ± {self.std(n):.2g}" for n in self.names]
        return "\n".join(
            lines
            + [f"χ²/dof = {self.chi2_dof:.3f} over {self.n_points} ring-downs"]
            + [
                f"polarity of the {name!r} wiring: {'as written' if sign > 0 else 'reversed'}"
                for name, sign in self.polarity.items()
            ]
            + [f"note: {n}" for n in self.notes]
        )
