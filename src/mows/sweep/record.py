"""The ring-downs of one rotation sweep as they arrive (:class:`SweepPoint` from each fit) and
their decomposition as a whole (:meth:`SweepRecord.decompose`), with the lab table they make."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from mows.estimate.ringdown.types import parameter_std
from mows.physics.probe import Probe
from mows.physics.ringdown_average import MAD_TO_SD, stop_from_swing_rad, stop_median_std_rad, swing_from_stop_rad
from mows.records import stamps
from mows.sweep.decompose import decompose
from mows.sweep.decomposition import Decomposition
from mows.sweep.shift_model import NeighbourFields, Ringdowns, local_potential

REST_OFFSET_STD_RAD = math.radians(1.0)  # a fitted rest offset is used when its σ is below this…
REST_OFFSET_SIGMAS = 4.0  # …and it is this many σ from 0
OUTLIER_SIGMAS = 3.0  # a pooled value this many robust σ from the median is left out
# Ring-downs that one static field describes this well are one sweep: its field gives each rest angle.
MAX_SWEEP_CHI2_DOF = 10.0


def robust_median(values, fallback: float = math.nan) -> float:
    """The median of ``values`` after leaving out those more than OUTLIER_SIGMAS robust σ
    (from the median absolute deviation) from the first median; ``fallback`` when empty."""
    values = np.asarray(values, float)
    if values.size == 0:
        return float(fallback)
    median = float(np.median(values))
    spread = MAD_TO_SD * float(np.median(np.abs(values - median)))
    kept = values[np.abs(values - median) <= OUTLIER_SIGMAS * spread] if spread > 0 else values
    return float(np.median(kept))


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
    start_offset_s: float = 0.0  # the fit's first sample after the coil switch-off (0: not recorded)

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
            float(fit.start_offset_s),
        )

    @classmethod
    def from_message(cls, fit) -> SweepPoint:
        """A successful RingdownFit message (live, or read from a bag: the fields are the same)
        at its device stamp, with the frequency shift the estimator published."""
        stamp_ns = stamps.nanoseconds(fit.header.stamp)
        return cls.from_fit(
            fit, fit.frequency_shift_hz, fit.frequency_shift_std_hz, stamp_ns / stamps.NS_PER_S, stamp_ns
        )


def sweep_numbers(theta0_rad: np.ndarray) -> np.ndarray:
    """The sweep (0, 1, …) of each ring-down of a recording, in order: a sweep measures each
    orientation once, so a ring-down at an orientation the current sweep has already measured
    (to 1e-6 rad) starts the next."""
    numbers = np.zeros(len(theta0_rad), int)
    seen: list[float] = []
    for i, angle in enumerate(np.asarray(theta0_rad, float)):
        if any(abs(math.remainder(angle - other, math.tau)) < 1e-6 for other in seen):
            numbers[i:] += 1
            seen = []
        seen.append(angle)
    return numbers


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
        REST_OFFSET_STD_RAD and the offset REST_OFFSET_SIGMAS σ from 0); NaN elsewhere (an
        offset that is noise would shorten the swing by ~0.8σ)."""
        offset = np.abs(self._column("rest_offset_rad"))
        std = self._column("rest_offset_std_rad")
        determined = (std <= REST_OFFSET_STD_RAD) & (offset > REST_OFFSET_SIGMAS * std)
        return np.where(determined, offset, np.nan)

    def _since_release(self) -> tuple[np.ndarray, np.ndarray]:
        """(δ, t) of each point: its damping and its fit's first sample's time after the
        switch-off, over which the swing released at the stop decays (:class:`Ringdowns`)."""
        return self._column("damping_per_s"), self._column("start_offset_s")

    def stop_amplitude_rad(self, rest_angles_rad=None, fallback_rad: float = math.nan) -> float:
        """The housing stop every ring-down starts from, as far from the lever's undeflected
        position: the median of θmax + |θs| over the points whose fit determined θmax (θmax grown
        back by e^(δ·t) to the switch-off; θs each point's rest angle, by default the fit's own
        rest offset where it determined it), after
        leaving out those more than OUTLIER_SIGMAS robust σ from it; ``fallback_rad`` (the
        probe's stop) where no point gives it. The median, because a few fits in a strong field
        sit in a wrong minimum with a small σ, and one such fit would lead an inverse-variance mean."""
        rest = self.rest_offsets_rad() if rest_angles_rad is None else np.asarray(rest_angles_rad, float)
        if not self.points:
            return fallback_rad
        stops = stop_from_swing_rad(self._column("amplitude_rad"), rest, *self._since_release())
        return robust_median(stops[np.isfinite(stops)], fallback_rad)

    def stop_std_rad(self, rest_angles_rad=None, fallback_std_rad: float = math.nan) -> float:
        """The standard uncertainty of :meth:`stop_amplitude_rad`: the median's standard error
        (:func:`mows.physics.ringdown_average.stop_median_std_rad`) where enough fits give the
        stop, else ``fallback_std_rad`` (the probe's stop's σ, written by its calibration)."""
        rest = self.rest_offsets_rad() if rest_angles_rad is None else np.asarray(rest_angles_rad, float)
        if not self.points:
            return fallback_std_rad
        std = stop_median_std_rad(stop_from_swing_rad(self._column("amplitude_rad"), rest, *self._since_release()))
        return std if math.isfinite(std) else fallback_std_rad

    def decompose(
        self,
        probe: Probe,
        f00_hz: float,
        model: str = "first_principles",
        f00_free: bool = False,
        neighbours: NeighbourFields | None = None,
        curvature: bool = False,
        measured: Ringdowns | None = None,
        start=None,
    ) -> Decomposition:
        """:func:`decompose` of every ring-down (not of per-angle means, so χ² keeps its dof).

        Each ring-down is weighted by its fit's own σ; the calibrated f00's σ, which the estimator
        folded into every shift's σ (σ_shift² = σ_f² + σ_f00²), is one error shared by all of
        them and enters the covariance as such (:func:`decompose`'s ``f00_std_hz``).

        The first-principles model needs the swing each ring-down starts with, stop − |θs|, and
        θs depends on the field it is fitting: a first pass with the fits' own rest offsets gives
        the field, its rest angles give the pooled stop (the probe's where no fit determined
        θmax), and a second pass fits with both. The stop's σ (:meth:`stop_std_rad`: the pooled
        stop's, else the probe file's ``theta_stop_std_rad``) enters the covariance as one error
        shared by every ring-down (:class:`Ringdowns`' ``stop_std_rad``). ``neighbours``: other
        probes' fields at each ring-down, known terms of the first-principles model
        (:mod:`mows.sweep.probes`);
        ``curvature``: fit the field's 3θ0 curvature too (:func:`decompose`). ``measured``: the
        ring-downs did not start from the stop (a multi-tone excitation's), and each starts with the
        θmax its fit measured (:meth:`measured_ringdowns`, None where a fit did not measure it).
        ``start``: the parameters to start from (:func:`decompose`'s), e.g. an earlier pass's.
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
            start=start,
        )
        if model != "first_principles":
            return decompose(**arrays)
        arrays.update(neighbours=neighbours, curvature=curvature)
        if measured is not None:
            return decompose(**arrays, ringdowns=measured)

        damping, duration, pickups = self._column("damping_per_s"), self._column("duration_s"), self.pickups()

        def ringdowns(rest=None):
            stop = self.stop_amplitude_rad(rest, probe.theta_stop_rad)
            std = self.stop_std_rad(rest, probe.theta_stop_std_rad)
            return Ringdowns(
                stop, damping, duration, pickups, start_offset_s=self._column("start_offset_s"), stop_std_rad=std
            )

        first = decompose(**arrays, ringdowns=ringdowns())
        if not first.ok:
            return first
        rest = self.rest_angles_rad(first, probe, neighbours)
        return decompose(**{**arrays, "start": first.parameters}, ringdowns=ringdowns(rest))

    def measured_ringdowns(self) -> Ringdowns | None:
        """The ring-downs as recorded when they do not start from the stop (a multi-tone
        excitation's): each starts with the θmax its fit measured, a joint fit's from the signal's
        size about the undeflected lever, which the model takes about its rest angle
        (:class:`Ringdowns`). None when a fit did not measure it."""
        swings = self._column("amplitude_rad")
        if not np.isfinite(swings).all():
            return None
        return Ringdowns(math.nan, self._column("damping_per_s"), self._column("duration_s"), self.pickups(), swings)

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

    def rest_angles_rad(
        self, decomposition: Decomposition, probe: Probe, neighbours: NeighbourFields | None = None
    ) -> np.ndarray:
        """|θs| of each ring-down at the decomposition's field and gradient, and the
        ``neighbours``' fields when given (0 where undefined)."""
        theta0 = self._column("theta0_rad")
        potential = local_potential(decomposition.parameters, theta0, probe, neighbours)
        return np.abs(np.nan_to_num(potential.rest_angle_rad()))

    def start_amplitudes_rad(self, decomposition: Decomposition, probe: Probe) -> np.ndarray:
        """Each ring-down's start swing at its fit's first sample
        (:func:`mows.physics.ringdown_average.swing_from_stop_rad`), θs at the decomposition's
        field and gradient, the stop pooled (the probe's where no fit gives it)."""
        rest = self.rest_angles_rad(decomposition, probe)
        return swing_from_stop_rad(self.stop_amplitude_rad(rest, probe.theta_stop_rad), rest, *self._since_release())

    def start_swings_rad(self, probe: Probe) -> tuple[np.ndarray, list[str]]:
        """Each ring-down's start swing, the record being one probe's released at the stop, and
        notes of how it was found: from the first-principles decomposition of all its ring-downs
        as one sweep in one static field (:meth:`start_amplitudes_rad`) where that describes them
        (χ²/dof ≤ ``MAX_SWEEP_CHI2_DOF``), else from each fit alone
        (:meth:`fitted_start_amplitudes_rad`, the probe's stop where no fit gives it)."""
        decomposition = self.decompose(probe, probe.f00_hz)
        if decomposition.ok and decomposition.chi2_dof <= MAX_SWEEP_CHI2_DOF:
            note = f"start swings: the stop less the rest angle in the sweep's field ({decomposition.report()})"
            return self.start_amplitudes_rad(decomposition, probe), [note]
        return self.fitted_start_amplitudes_rad(probe.theta_stop_rad)

    def fitted_start_amplitudes_rad(self, stop_rad: float = math.nan) -> tuple[np.ndarray, list[str]]:
        """Each ring-down's start swing from its fit alone, and notes of what was assumed: the
        fit's θmax where it determined it within the stop, else stop − |θs − θ0| with the fit's rest
        offset decayed to its first sample (the stop pooled, ``stop_rad`` where no fit gives it);
        where a fit determined neither, the probe is taken as undeflected."""
        rest = self.rest_offsets_rad()
        stop = self.stop_amplitude_rad(fallback_rad=stop_rad)
        amplitude = self._column("amplitude_rad")
        beyond = amplitude > stop  # no swing about the rest angle is wider than the stop
        amplitude[beyond] = np.nan
        released = swing_from_stop_rad(stop, np.nan_to_num(rest), *self._since_release())
        start = np.where(np.isfinite(amplitude), amplitude, released)
        unknown = np.count_nonzero(~np.isfinite(rest) & ~np.isfinite(amplitude))
        notes = []
        if beyond.any():
            notes.append(f"{np.count_nonzero(beyond)} fits' θmax beyond the stop {math.degrees(stop):.2f}°: not used")
        if not np.isfinite(self.stop_amplitude_rad()) and math.isfinite(stop_rad):
            notes.append(
                f"no fit determined θmax and the rest offset: the stop is the probe's {math.degrees(stop_rad):.2f}°"
            )
        if unknown:
            notes.append(
                f"{unknown} of {len(rest)} ring-downs determined neither θmax nor their rest offset: "
                "their start swing is the stop, as if undeflected"
            )
        if not np.isfinite(start).all():
            notes.append(f"{np.count_nonzero(~np.isfinite(start))} start swings unknown: no stop from fits or probe")
        return start, notes

    def table_columns(self, start_amplitudes_rad=None) -> dict:
        """Columns of a model-lab measurement table (docs/model_lab.md). ``amplitude_deg`` is each
        ring-down's start swing: ``start_amplitudes_rad`` (e.g. :meth:`start_amplitudes_rad` of
        a decomposition), else the pooled :meth:`stop_amplitude_rad` less the fit's own rest
        offset |θs − θ0| (the swing about a deflected rest angle ends at the nearer stop)."""
        t = self._column("t_s")
        start = (
            self.fitted_start_amplitudes_rad()[0]
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
