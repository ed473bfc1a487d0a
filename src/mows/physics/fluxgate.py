"""Single-axis fluxgate sensors (Methods: FL1-10, ±10 µT, 0.1 nT, 20 kS/s) and their noise.

Pick-up. :func:`dipole_pickup_t` gives the exact field of the moving magnet (a point dipole)
along a sensor's axis at every time sample: Eq. S8 without its far-field reduction. On the
sensor line with the moment in the plane it reduces to S = κ·(2a·cos θ − b·sin θ),
κ = μ0·m/(4π r³) (Eqs. S8, S9); the difference of two parallel sensors at r and r + d is the
same with r_eff = (1/r³ − 1/(r + d)³)^(−1/3) (Eq. S10). The paper's pair
(:meth:`FluxgatePair.paper`) sits on the +x axis at r = 6 cm with axes along global y (b = 1);
d is not given in the paper and follows from its r_eff = 6.75 cm: d = 2.99 cm.

Digitisation. :func:`digitise` subtracts the sensor's ``offset_t``, flags and clips values
beyond ±``range_t`` (the paper's sensors saturate during excitation), and rounds to the
nearest multiple of ``resolution_t``.

Offset nulling. With a ±10 µT range a fluxgate would saturate in the Earth's field (≈ 50 µT).
The instruments compensate a static field; we model that as a constant ``offset_t``
subtracted from the reading, set by :meth:`Fluxgate.with_offset_nulled` so that a given static
field reads zero. The signal of the ringing magnet (and any change of the static field)
remains.

Noise (:class:`NoiseModel`). Common-mode noise, identical on both sensors: white, 1/f
("pink") and optionally mains hum; independent white noise per sensor. Levels are one-sided
amplitude spectral densities in T/√Hz (the pink level is its ASD at 1 Hz); the difference
of the two channels removes the common part exactly. The simulator draws it
(:class:`mows.sim.noise.NoiseStream`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import ArrayLike

from mows.physics.pose import Pose
from mows.physics.schema import Vector, unit_vector3, vector3
from mows.physics.sources import MU0_OVER_4PI, dipole_field_t

FL1_RANGE_T = 10e-6
FL1_RESOLUTION_T = 1e-10
DAQ_SAMPLE_RATE_HZ = 20e3

PAPER_DISTANCE_M = 0.06
PAPER_EFFECTIVE_DISTANCE_M = 0.0675


def spacing_for_effective_distance_m(distance_m: float, effective_distance_m: float) -> float:
    """Sensor spacing d that gives r_eff at distance r: Eq. S10 solved for d, metres."""
    if not 0.0 < distance_m < effective_distance_m:
        raise ValueError(f"need 0 < distance_m < effective_distance_m, got {distance_m!r}, {effective_distance_m!r}")
    return (distance_m**-3 - effective_distance_m**-3) ** (-1.0 / 3.0) - distance_m


PAPER_SPACING_M = spacing_for_effective_distance_m(PAPER_DISTANCE_M, PAPER_EFFECTIVE_DISTANCE_M)


@dataclass(frozen=True, eq=False)
class Fluxgate:
    """A single-axis fluxgate at ``position_m`` reading the field along unit vector ``axis``.

    ``range_t``: saturation at ±range (tesla); ``resolution_t``: quantisation step (tesla);
    ``offset_t``: static field compensated by the instrument, subtracted from the reading.
    """

    position_m: np.ndarray
    axis: np.ndarray
    range_t: float = FL1_RANGE_T
    resolution_t: float = FL1_RESOLUTION_T
    offset_t: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_m", vector3("position_m", self.position_m))
        object.__setattr__(self, "axis", unit_vector3("axis", self.axis))
        for name in ("range_t", "resolution_t"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} must be a finite field > 0 T, got {value!r}")
        if not np.isfinite(self.offset_t):
            raise ValueError(f"offset_t must be finite, got {self.offset_t!r}")

    def component_t(self, field_t: ArrayLike) -> np.ndarray:
        """The component along the sensor axis of fields ``field_t`` (..., 3), tesla."""
        return np.asarray(field_t, dtype=float) @ self.axis

    def with_offset_nulled(self, static_field_t: ArrayLike) -> Fluxgate:
        """This sensor with its offset set so that the static field ``static_field_t`` (3,) reads 0."""
        return replace(self, offset_t=float(self.component_t(static_field_t)))


def dipole_pickup_t(sensor: Fluxgate, magnet_positions_m: ArrayLike, moments_am2: ArrayLike) -> np.ndarray:
    """Exact dipole field along ``sensor.axis``, tesla, one value per time sample.

    ``magnet_positions_m`` and ``moments_am2`` are (n, 3) (or broadcastable): the magnet's
    position and moment at each sample. Eq. S8 in its exact form.
    """
    offsets = sensor.position_m - np.asarray(magnet_positions_m, dtype=float)
    return dipole_field_t(moments_am2, offsets) @ sensor.axis


def digitise(values_t: ArrayLike, sensor: Fluxgate) -> tuple[np.ndarray, np.ndarray]:
    """The sensor's digital reading of the field component ``values_t`` (tesla).

    Returns (readings_t, saturated): readings are values − offset, clipped to ±range and
    rounded to the nearest multiple of the resolution; ``saturated`` flags the samples that
    were beyond the range.
    """
    values = np.asarray(values_t, dtype=float) - sensor.offset_t
    saturated = np.abs(values) > sensor.range_t
    readings = np.clip(np.round(values / sensor.resolution_t) * sensor.resolution_t, -sensor.range_t, sensor.range_t)
    return readings, saturated


@dataclass(frozen=True, eq=False)
class FluxgatePair:
    """Two parallel sensors on one line with the probe; column 0 is the near one."""

    sensors: tuple

    def __post_init__(self) -> None:
        object.__setattr__(self, "sensors", tuple(self.sensors))
        if len(self.sensors) != 2 or not all(isinstance(s, Fluxgate) for s in self.sensors):
            raise ValueError(f"sensors must be two Fluxgate objects, got {self.sensors!r}")

    @classmethod
    def paper(
        cls,
        probe_position_m: ArrayLike = (0.0, 0.0, 0.0),
        distance_m: float = PAPER_DISTANCE_M,
        spacing_m: float = PAPER_SPACING_M,
        direction: ArrayLike = (1.0, 0.0, 0.0),
        axis: ArrayLike = (0.0, 1.0, 0.0),
    ) -> FluxgatePair:
        """The paper's pair: sensors at r and r + d from the probe along ``direction``, reading
        along ``axis`` (global y: b = 1 in Eq. S9)."""
        probe = vector3("probe_position_m", probe_position_m)
        line, reading = unit_vector3("direction", direction), unit_vector3("axis", axis)
        return cls(
            (Fluxgate(probe + distance_m * line, reading), Fluxgate(probe + (distance_m + spacing_m) * line, reading))
        )

    @property
    def positions_m(self) -> np.ndarray:
        """Sensor positions, shape (2, 3)."""
        return np.stack([s.position_m for s in self.sensors])

    def pickup_t(self, magnet_positions_m: ArrayLike, moments_am2: ArrayLike) -> np.ndarray:
        """:func:`dipole_pickup_t` of both sensors, shape (n, 2)."""
        return np.stack([dipole_pickup_t(s, magnet_positions_m, moments_am2) for s in self.sensors], axis=-1)

    def component_t(self, fields_t: ArrayLike) -> np.ndarray:
        """Axis components of fields (..., 2, 3) at the two sensors: shape (..., 2)."""
        return np.stack([s.component_t(np.asarray(fields_t)[..., i, :]) for i, s in enumerate(self.sensors)], axis=-1)

    def with_offsets_nulled(self, static_fields_t: ArrayLike) -> FluxgatePair:
        """Both offsets set to null the static fields (2, 3) at the two sensors."""
        fields = np.asarray(static_fields_t, dtype=float)
        return replace(self, sensors=tuple(s.with_offset_nulled(f) for s, f in zip(self.sensors, fields)))

    def digitise(self, values_t: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """:func:`digitise` of columns (n, 2); returns (readings_t, saturated), both (n, 2)."""
        values = np.asarray(values_t, dtype=float)
        columns = [digitise(values[..., i], s) for i, s in enumerate(self.sensors)]
        return np.stack([c[0] for c in columns], axis=-1), np.stack([c[1] for c in columns], axis=-1)


PICKUP_COMBINATIONS = {"difference": (1.0, -1.0), "channel1": (1.0, 0.0), "channel2": (0.0, 1.0)}


def paper_pickup(theta0_rad: ArrayLike, direction: Vector = (0.0, 1.0)) -> np.ndarray:
    """Eq. S11 as a pickup series, C_0 = 0 and C_1 = (2a + ib)·e^(iθ0): the signal
    2a·cos θ − b·sin θ = Re(C_1·e^(ix)) at θ = θ0 + x, (a, b) the sensing direction (the
    paper's is (0, 1)). Shape ``np.shape(theta0_rad) + (2,)``."""
    a, b = direction
    first = complex(2.0 * a, b) * np.exp(1j * np.asarray(theta0_rad, float))
    return np.stack([np.zeros_like(first), first], axis=-1)


def pickup_harmonics(
    pair: FluxgatePair,
    pose: Pose,
    lever_m: float,
    moment_am2: float,
    combine: str = "difference",
    order: int = 6,
    points: int = 64,
) -> np.ndarray:
    """The sensor signal as a Fourier series in the deflection: S(θt) = Σ_k Re(C_k·e^(ikθt)).

    The magnet swings on its lever, so its position moves with its moment: the exact dipole
    pickup (Eq. S8 without the far-field and fixed-position approximations) is a smooth
    periodic function of θt whose harmonics fall off like (3l/r)^k. Returned normalised by the
    κ of Eq. S11 for this combination (μ0·m/4π over r³ or r_eff³, Eq. S10), so a fit's κ keeps
    its meaning. For a magnet turning in place (l = 0) the series is the paper's model exactly:
    C_1 = (2a + ib)·e^(iθ0), all others 0, with (a, b) the sensing axis.

    Parameters
    ----------
    pose : :class:`mows.physics.pose.Pose` with the probe's orientation θ0.
    combine : 'difference' (near − far), 'channel1' or 'channel2'.
    order : highest harmonic kept (the rest is below 1e-7 of the signal for the paper's set-up).
    """
    weights = np.array(PICKUP_COMBINATIONS[combine])
    theta = 2.0 * np.pi * np.arange(points) / points - np.pi
    moments = moment_am2 * pose.moment_direction_at(theta)
    signal = pair.pickup_t(pose.magnet_position_at(theta, lever_m), moments) @ weights
    # rfft refers phases to θ = −π: multiply by (−1)^k to refer them to θt = 0.
    coefficients = np.fft.rfft(signal)[: order + 1] / points * (-1.0) ** np.arange(order + 1)
    coefficients[1:] *= 2.0
    return coefficients / pickup_scale_t(pair, pose.magnet_position_m, moment_am2, combine)


def pickup_scale_t(
    pair: FluxgatePair, magnet_position_m: ArrayLike, moment_am2: float, combine: str = "difference"
) -> float:
    """The κ of Eq. S11 for the combination ``combine`` (μ0·m/4π over r³ or r_eff³, Eq. S10),
    T: what :func:`pickup_harmonics` is normalised by, so that κ times its series is the
    sensors' signal in tesla."""
    weights = np.array(PICKUP_COMBINATIONS[combine])
    distances = np.linalg.norm(pair.positions_m - np.asarray(magnet_position_m, float), axis=1)
    return float(MU0_OVER_4PI * moment_am2 * (distances**-3.0 @ weights))


@dataclass(frozen=True)
class NoiseModel:
    """Magnetometer noise; all levels are one-sided ASDs in T/√Hz except ``mains_t``.

    Parameters
    ----------
    common_white_t_per_rthz : white noise common to both sensors.
    common_pink_t_per_rthz_at_1hz : 1/f noise common to both sensors, ASD at 1 Hz
        (ASD ∝ f^(−1/2)).
    sensor_white_t_per_rthz : independent white noise of each sensor.
    mains_t, mains_hz : common mains hum, peak amplitude (tesla) and frequency; random phase.
    """

    common_white_t_per_rthz: float = 0.0
    common_pink_t_per_rthz_at_1hz: float = 0.0
    sensor_white_t_per_rthz: float = 0.0
    mains_t: float = 0.0
    mains_hz: float = 50.0

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} must be finite and ≥ 0, got {value!r}")

    def difference_white_std_t(self, sample_rate_hz: float) -> float:
        """σ per sample of the pair's difference channel from the sensors' own white noise, T:
        the common-mode noise cancels; each sensor's one-sided ASD over the band fs/2 gives
        asd·√(fs/2), and the difference of two independent ones √2 times that."""
        return float(self.sensor_white_t_per_rthz * math.sqrt(sample_rate_hz))
