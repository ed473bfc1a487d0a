"""The ring-down fit's vocabulary: its options, what it is told of each probe, its result and
the outcome codes.

:func:`mows.estimate.ringdown.fit_ringdowns` takes a :class:`ProbeLine` per probe ringing in
the window and :class:`FitOptions`, and returns a :class:`RingdownFit` per probe whose
:class:`FitStatus` says whether the numbers mean anything; the estimator node, the calibration
and the lab read these without running a fit.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Iterable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from mows.physics.fluxgate import FluxgatePair, paper_pickup, pickup_harmonics
from mows.physics.pose import Pose
from mows.physics.probe import Probe


class FitStatus(enum.IntEnum):
    """Outcome of a fit; the numbers match ``mows_msgs/RingdownFit`` STATUS_* constants."""

    OK = 0
    TOO_SHORT = 1
    INVALID_SAMPLES = 2
    SATURATED = 3
    NO_OSCILLATION = 4
    BAD_SAMPLE_RATE = 5
    NEGATIVE_STIFFNESS = 6
    NOT_CONVERGED = 7
    DATA_GAP = 8
    BAD_FIT = 9


@dataclasses.dataclass(frozen=True)
class FitOptions:
    """How to fit. Frequencies in Hz, times in s, angles in rad.

    channels : 'difference' (channel 1 − channel 2: cancels common-mode noise),
        'both' (joint fit, a κ and an offset per channel), 'channel1' or 'channel2'.
    sensor_direction : (a, b) of the sensing axis in the rotation plane (Eq. S11), for the
        paper's model.
    pickup : coefficients C_k (complex, k = 0 …) of g for the commanded θ0, from
        :func:`mows.physics.fluxgate.pickup_harmonics`; replaces the paper's model when given.
    theta0_free : fit θ0 instead of taking the commanded value (paper's model of one probe only:
        the pickup's dependence on θ0 is not a rotation once the lever moves the magnet).
    rest_offset_free : fit the rest-angle offset ε = θs − θ0 (the static deflection by a
        perpendicular field, gravity or a gradient). The lever turns by ε about its pivot, so
        the signal is g(ε + x): the pickup turned by ε, exact for any pickup. Without it the
        model swings about θ0, and κ and θmax trade off against the missing offset (θmax
        off by up to 50° near θ0 = 180° in a strong perpendicular field); f barely moves.
        With ``theta0_free`` the same parameter is reported as θ0 instead. Fitted for one probe
        only (:mod:`mows.estimate.ringdown.fit` says why).
    search_fraction : the spectral search covers expected f ± this fraction.
    min_periods : fewer usable periods than this gives TOO_SHORT.
    min_frequency_fraction : a peak below this fraction of the expected frequency means the
        probe has (nearly) no restoring spring: NEGATIVE_STIFFNESS.
    detection_snr : the spectral peak must exceed the noise floor by this power ratio.
    max_chi2_dof : above this the model does not describe the data: BAD_FIT.
    max_iterations : the Levenberg–Marquardt budget of each stage (trial steps, rejected ones too).
    theta_stop_rad : the housing stop: the rest offset is searched within ±stop (a probe
        deflected beyond it rests on the stop) and θmax within 2·stop.
    amplitude_tolerance_rad, rest_offset_tolerance_rad : θmax and the rest offset are reported
        only where the data pin them within these: no other minimum of the cost that differs
        by more than half of it fits nearly as well, and their σ is below a third of it.
        Elsewhere they are NaN, named in ``RingdownFit.undetermined``, the reason in the message.
    """

    channels: str = "difference"
    sensor_direction: tuple = (0.0, 1.0)
    pickup: tuple | None = None
    theta0_free: bool = False
    rest_offset_free: bool = True
    search_fraction: float = 0.3
    min_periods: float = 10.0
    min_frequency_fraction: float = 0.2
    detection_snr: float = 30.0
    max_chi2_dof: float = 25.0
    max_iterations: int = 60
    theta_stop_rad: float = math.radians(45.0)
    amplitude_tolerance_rad: float = math.radians(1.0)
    rest_offset_tolerance_rad: float = math.radians(0.5)

    def __post_init__(self) -> None:
        if self.channels not in ("difference", "both", "channel1", "channel2"):
            raise ValueError(f"channels = {self.channels!r}; use difference, both, channel1 or channel2")
        if not 0.0 < self.search_fraction < 1.0:
            raise ValueError(f"search_fraction = {self.search_fraction} must be in (0, 1)")
        if self.pickup is not None and (self.theta0_free or self.channels == "both"):
            raise ValueError(
                "a pickup series describes one fixed-θ0 channel: it cannot be combined with "
                "theta0_free or channels='both'"
            )

    @classmethod
    def lever_aware(
        cls, pair: FluxgatePair, probe: Probe, theta0_rad: float, channels: str = "difference", **others: Any
    ) -> FitOptions:
        """Options with the exact pickup of ``probe``'s magnet swinging on its lever, seen by the
        fluxgate ``pair`` (:class:`mows.physics.fluxgate.FluxgatePair`) with the probe at θ0, the
        rest offset searched within ``probe``'s housing stop."""
        pickup = pickup_harmonics(pair, Pose(theta0_rad=theta0_rad), probe.lever_m, probe.moment_am2, combine=channels)
        return cls(channels=channels, pickup=tuple(pickup), theta_stop_rad=probe.theta_stop_rad, **others)

    @property
    def offset_free(self) -> bool:
        """The fit has a fifth nonlinear parameter that turns the pickup: θ0 or the rest offset."""
        return self.theta0_free or self.rest_offset_free

    def pickup_at(self, theta0_rad: float) -> NDArray[np.complex128]:
        """The coefficients C_k of g: the given pickup, or the paper's single term."""
        if self.pickup is not None:
            return np.asarray(self.pickup, complex)
        return paper_pickup(theta0_rad, self.sensor_direction)


@dataclasses.dataclass(frozen=True)
class ProbeLine:
    """What the fit is told about one probe ringing in the window.

    probe_id : carried into its :class:`RingdownFit`.
    theta0_rad : its commanded orientation.
    expected_frequency_hz : where its line is, e.g. its excitation frequency.
    pickup : the C_k of its g (:func:`mows.physics.fluxgate.pickup_harmonics`, for the fitted
        channel combination); None: ``FitOptions.pickup``, else the paper's single term.
    damping_guess_per_s : δ to start from.
    pickup_scale_t : the κ that makes ``pickup`` the sensors' signal in tesla
        (:func:`mows.physics.fluxgate.pickup_scale_t`); NaN: unknown. Known, it gives the
        swing from the signal's size where the signal's shape does not
        (:func:`mows.estimate.ringdown.summary.swing_from_signal_rad`).
    """

    probe_id: int
    theta0_rad: float
    expected_frequency_hz: float
    pickup: tuple | None = None
    damping_guess_per_s: float = 1.8
    pickup_scale_t: float = math.nan

    def pickup_series(self, options: FitOptions = FitOptions()) -> NDArray[np.complex128]:
        """Its C_k: ``pickup``, else ``options``' (:meth:`FitOptions.pickup_at` its θ0)."""
        if self.pickup is None:
            return options.pickup_at(self.theta0_rad)
        return np.asarray(self.pickup, complex)


@dataclasses.dataclass
class RingdownFit:
    """Result of :func:`mows.estimate.ringdown.fit_ringdowns` for one probe. SI units; every
    number is NaN unless status is OK.

    ``amplitude_rad`` is θmax, the swing at the first fitted sample about the rest angle
    θ0 + ``rest_offset_rad``; its σ is :attr:`amplitude_std_rad`. Each is NaN, named in
    ``undetermined`` with the reason in ``message``, where the data do not pin it within
    ``FitOptions.amplitude_tolerance_rad`` / ``rest_offset_tolerance_rad`` (another minimum of
    the cost fits nearly as well, or its σ is too large, or θmax ran to its bound). Any parameter
    whose variance came out below zero (a numerically singular covariance) is NaN with its
    covariance row and column, and named there too. The offset's sign is fixed through κ > 0;
    where its mirror image fits as well (near θ0 = 90° the signal is even in the deflection) the
    offset is not reported.
    """

    status: FitStatus
    message: str = ""
    theta0_rad: float = math.nan
    theta0_free: bool = False
    frequency_hz: float = math.nan
    frequency_std_hz: float = math.nan
    frequency_crb_hz: float = math.nan
    damping_per_s: float = math.nan
    amplitude_rad: float = math.nan
    rest_offset_rad: float = math.nan
    phase_rad: float = math.nan
    kappa_t: float = math.nan
    offset_t: float = math.nan
    chi2_dof: float = math.nan
    r_squared: float = math.nan
    snr_db: float = math.nan
    noise_std_t: float = math.nan
    n_samples: int = 0
    duration_s: float = 0.0
    start_offset_s: float = 0.0
    parameter_names: tuple = ()
    covariance: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 0)))
    pickup: tuple = ()  # the fitted model's C_k (complex) over the swing about the rest angle
    undetermined: tuple = ()  # names of the numbers the data did not pin (NaN; why: ``message``)
    probe_id: int = 0  # which probe (:class:`ProbeLine`), when several ring down together

    @property
    def ok(self) -> bool:
        return self.status == FitStatus.OK

    @property
    def amplitude_std_rad(self) -> float:
        """σ of θmax from the covariance; NaN when θmax was not determined (``amplitude_rad`` NaN)."""
        if not math.isfinite(self.amplitude_rad):
            return math.nan
        return parameter_std(self.parameter_names, self.covariance, "amplitude_rad")

    def _amplitude_text(self) -> str:
        if not math.isfinite(self.amplitude_rad):
            return "not determined"
        degrees, std_rad = math.degrees(self.amplitude_rad), self.amplitude_std_rad
        if math.isfinite(std_rad):
            text = f"{degrees:.2f} ± {math.degrees(std_rad):.2f}°"
        else:
            text = f"{degrees:.2f}° (its σ not determined)"
        if math.isfinite(self.rest_offset_rad):
            text += f" about a rest offset {math.degrees(self.rest_offset_rad):+.2f}°"
        return text

    def report(self) -> str:
        if not self.ok:
            return f"ring-down fit: {self.status.name}: {self.message}"
        return (
            f"f = {self.frequency_hz:.6f} ± {self.frequency_std_hz * 1e3:.4f} mHz "
            f"(CRB {self.frequency_crb_hz * 1e3:.4f} mHz), δ = {self.damping_per_s:.4f} 1/s, "
            f"θmax = {self._amplitude_text()}, θ0 = {math.degrees(self.theta0_rad):.2f}°, "
            f"χ²/dof = {self.chi2_dof:.3f}, R² = {self.r_squared:.5f}, SNR = {self.snr_db:.1f} dB, "
            f"{self.n_samples} samples over {self.duration_s:.3f} s"
        )


def parameter_std(names: Iterable[str], covariance: ArrayLike, name: str) -> float:
    """σ of parameter ``name`` from a fit's row-major ``covariance`` over ``names`` (a RingdownFit
    or its message); NaN when the fit has no such parameter or did not determine it."""
    names = list(names)
    if name not in names:
        return math.nan
    index = names.index(name)
    variance = float(np.asarray(covariance, float).reshape(len(names), len(names))[index, index])
    return math.sqrt(variance) if variance > 0 else math.nan


def failure(status: FitStatus, message: str, **known: Any) -> RingdownFit:
    return RingdownFit(status=status, message=message, **known)
