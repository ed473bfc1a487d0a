"""The ring-downs of one rotation sweep as they arrive (:class:`SweepPoint` from each fit) and
their decomposition as a whole (:meth:`SweepRecord.decompose`), with the lab table they make."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from mows.estimate.ringdown_types import parameter_std
from mows.physics.probe import Probe
from mows.sweep.decompose import Decomposition, Ringdowns, decompose, local_potential

REST_OFFSET_STD_RAD = math.radians(1.0)  # a fitted rest offset is used when its σ is below this…
REST_OFFSET_SIGMAS = 4.0  # …and it is this many σ from 0


def fitted_pickup(fit) -> tuple:
    """The pickup series a fit used: ``pickup`` of a RingdownFit, ``pickup_real``/``pickup_imag``
    of a RingdownFit message; () when it does not say (an older recording)."""
    if hasattr(fit, "pickup_real"):
        return tuple(complex(re, im) for re, im in zip(fit.pickup_real, fit.pickup_imag, strict=True))
    return tuple(getattr(fit, "pickup", ()))


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
    stamp_ns: int = 0  # the device stamp t_s was taken from, exact (0: none)
    rest_offset_rad: float = math.nan  # the fit's rest-angle offset θs − θ0 (NaN: not fitted)
    rest_offset_std_rad: float = math.nan
    pickup: tuple = ()  # the fit's pickup series C_k (complex); empty: unknown, Eq. S11 assumed

    @classmethod
    def from_fit(cls, fit, shift_hz: float, shift_std_hz: float, t_s: float = 0.0, stamp_ns: int = 0) -> SweepPoint:
        """A successful ring-down fit (:class:`mows.estimate.ringdown.RingdownFit`, or a RingdownFit
        message: the fields are the same) with its frequency shift; σ of θmax from the fit's
        covariance (NaN when θmax was not determined)."""
        amplitude_std = parameter_std(fit.parameter_names, fit.covariance, "amplitude_rad")
        return cls(
            fit.theta0_rad,
            fit.frequency_hz,
            fit.frequency_std_hz,
            shift_hz,
            shift_std_hz,
            fit.amplitude_rad,
            fit.damping_per_s,
            fit.duration_s,
            t_s,
            amplitude_std,
            int(stamp_ns),
            float(getattr(fit, "rest_offset_rad", math.nan)),
            parameter_std(fit.parameter_names, fit.covariance, "rest_offset_rad"),
            fitted_pickup(fit),
        )


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

    def rest_offsets_rad(self) -> np.ndarray:
        """|θs − θ0| of each point as its fit measured it, where the fit determined it (σ below
        REST_OFFSET_STD_RAD and the offset REST_OFFSET_SIGMAS σ from 0); 0 elsewhere. In a mT
        field a few fits sit in a wrong minimum (−10 ± 3° where the truth is 3.4°), and |ε| of an
        offset that is noise would shorten the swing by ~0.8σ: neither is used."""
        offset = np.abs(self._column("rest_offset_rad"))
        std = self._column("rest_offset_std_rad")
        determined = (std <= REST_OFFSET_STD_RAD) & (offset > REST_OFFSET_SIGMAS * std)
        return np.where(determined & np.isfinite(offset), offset, 0.0)

    def stop_amplitude_rad(self, rest_angles_rad=None) -> float:
        """The swing a ring-down starts with when the probe rests undeflected: the
        inverse-variance weighted mean of the fits' θmax + |θs| (θs: each point's rest angle,
        by default the fit's own rest offset, 0 where it has none).

        Every ring-down starts from the housing stop, and the perpendicular excitation scheme
        drives every orientation alike; a single fit's θmax, though, is poorly determined near
        θ0 = 180° (NaN when not determined at all), so the sweep's pooled value is the better
        input to the amplitude-dependent springs. The median when no σ is known.
        """
        rest = self.rest_offsets_rad() if rest_angles_rad is None else np.abs(np.asarray(rest_angles_rad, float))
        amplitude = self._column("amplitude_rad") + rest
        std = self._column("amplitude_std_rad")
        usable = np.isfinite(std) & (std > 0) & np.isfinite(amplitude)
        if not usable.any():
            return float(np.nanmedian(amplitude)) if np.isfinite(amplitude).any() else math.nan
        weights = 1.0 / std[usable] ** 2
        return float(weights @ amplitude[usable] / weights.sum())

    def decompose(
        self, probe: Probe, f00_hz: float, model: str = "first_principles", f00_free: bool = False
    ) -> Decomposition:
        """:func:`decompose` of every ring-down (not of per-angle means, so χ² keeps its dof).

        Each ring-down is weighted by its fit's own σ; the calibrated f00's σ, which the estimator
        folded into every shift's σ (σ_shift² = σ_f² + σ_f00²), is one error shared by all of
        them and enters the covariance as such (:func:`decompose`'s ``f00_std_hz``).

        The first-principles model needs the swing each ring-down starts with, stop − |θs|, and
        θs depends on the field it is fitting: a first pass with θs = 0 gives the field, its rest
        angles give the pooled stop amplitude, and a second pass fits with both.
        """
        theta0 = self._column("theta0_rad")
        arrays: dict[str, Any] = dict(
            theta0_rad=theta0,
            shift_hz=self._column("shift_hz"),
            shift_std_hz=self._column("frequency_std_hz"),
            probe=probe,
            f00_hz=f00_hz,
            model=model,
            f00_free=f00_free,
            f00_std_hz=self.f00_std_hz(),
        )
        if model != "first_principles":
            return decompose(**arrays)

        damping, duration, pickups = self._column("damping_per_s"), self._column("duration_s"), self.pickups()

        def ringdowns(stop):
            return Ringdowns(stop, damping, duration, pickups)

        first = decompose(**arrays, ringdowns=ringdowns(self.stop_amplitude_rad()))
        if not first.ok:
            return first
        stop = self.stop_amplitude_rad(self.rest_angles_rad(first, probe))
        return decompose(**arrays, ringdowns=ringdowns(stop), start=first.parameters)

    def pickups(self) -> np.ndarray | None:
        """Every ring-down's pickup series C_k (n, K + 1), zero-padded to the longest; None when
        any fit did not say which it used (the averaging then assumes Eq. S11's sensing axis)."""
        series = [p.pickup for p in self.points]
        if not series or not all(series):
            return None
        table = np.zeros((len(series), max(map(len, series))), complex)
        for row, coefficients in zip(table, series):
            row[: len(coefficients)] = coefficients
        return table

    def f00_std_hz(self) -> float:
        """The calibrated f00's σ the shifts carry: √(σ_shift² − σ_f²), the largest over the ring-downs."""
        excess = self._column("shift_std_hz") ** 2 - self._column("frequency_std_hz") ** 2
        return float(np.sqrt(np.max(excess, initial=0.0)))

    def rest_angles_rad(self, decomposition: Decomposition, probe: Probe) -> np.ndarray:
        """|θs| of each ring-down at the decomposition's field and gradient (0 where undefined)."""
        theta0 = self._column("theta0_rad")
        return np.abs(np.nan_to_num(local_potential(decomposition.parameters, theta0, probe).rest_angle_rad()))

    def start_amplitudes_rad(self, decomposition: Decomposition, probe: Probe) -> np.ndarray:
        """Each ring-down's start swing, stop − |θs|, at the decomposition's field and gradient."""
        rest = self.rest_angles_rad(decomposition, probe)
        return self.stop_amplitude_rad(rest) - rest

    def table_columns(self, start_amplitudes_rad=None) -> dict:
        """Columns of a model-lab measurement table (docs/model_lab.md). ``amplitude_deg`` is each
        ring-down's start swing: ``start_amplitudes_rad`` (e.g. :meth:`start_amplitudes_rad` of
        a decomposition), else the pooled :meth:`stop_amplitude_rad` less the fit's own rest
        offset |θs − θ0| (the swing about a deflected rest angle ends at the nearer stop)."""
        t = self._column("t_s")
        start = (
            self.stop_amplitude_rad() - self.rest_offsets_rad()
            if start_amplitudes_rad is None
            else np.asarray(start_amplitudes_rad, float)
        )
        return {
            "theta0_deg": np.degrees(self._column("theta0_rad")),
            "f_hz": self._column("frequency_hz"),
            "f_std_hz": self._column("frequency_std_hz"),
            "t_s": t - (t.min() if t.size else 0.0),
            "amplitude_deg": np.degrees(start),
            "damping_per_s": self._column("damping_per_s"),
            "duration_s": self._column("duration_s"),
        }
