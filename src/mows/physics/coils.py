"""Excitation coils of the paper's two setups (Methods) and their current schemes.

Two coils drive the magnet at resonance. Coil k carries A·sin(θ0 + φ_k), A the base
amplitude (≤ 10 A) and θ0 the probe orientation in the global x–y plane, so that the total
coil field at the probe is perpendicular to the moment direction (cos θ0, sin θ0) for every
θ0. With coil fields at the probe along unit vectors u1, u2 and magnitude b per ampere,

* largest-spacing setup, φ = (135°, 45°), u1 = (cos 45°, sin 45°), u2 = (cos 135°, sin 135°):
  sin(θ0 + 135°)·u1 + sin(θ0 + 45°)·u2 = (−sin θ0, cos θ0);
* Helmholtz setup, φ = (90°, 0°), u1 = +y, u2 = −x:
  cos θ0·(0, 1) + sin θ0·(−1, 0) = (−sin θ0, cos θ0).

Both give A·b·(−sin θ0, cos θ0): a field of constant magnitude, turned with the probe,
exactly perpendicular to the moment at the probe (the coil axes pass through it).

Geometry (the paper gives the schemes, not the distances; the distances are assumptions):
largest spacing, coil 1 centred 10 cm from the probe along 225°, coil 2 along 315°, both
axes towards the probe (the fluxgates are on +x, the coils stay in the y < 0 half-plane);
Helmholtz setup, coil 1 10 cm along −y with axis +y, coil 2 10 cm along −x with axis −x
(the winding sense that makes its field at the probe point along −x). The static-field
Helmholtz pair of that setup (Pasco EM-6723A, radius = spacing = 10.5 cm, axis x) is
:func:`pasco_pair`.

The coils are LSIP-330 air coils (3.3 mH): modelled as :func:`mows.physics.field.solenoid` of
:data:`LSIP330_TURNS` turns, radius :data:`LSIP330_RADIUS_M`, length :data:`LSIP330_LENGTH_M`
(assumed dimensions; the inductance is carried for information only).

YAML form (:func:`setup_from_dict`, :meth:`CoilSetup.to_dict`)::

    {preset: largest_spacing | helmholtz, distance_m: 0.10, current_limit_a: 10.0, probe_position_m: [0, 0, 0]}
    {name: custom, coils: [<field source>, ...], current_phases_deg: [135, 45],
     inductance_h: 3.3e-3, current_limit_a: 10.0}

Coil sources are fields per ampere; degrees appear only in the YAML key ``current_phases_deg``.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from mows.physics import ranges
from mows.physics.field import (
    FieldSource,
    anti_helmholtz_pair,
    helmholtz_pair,
    solenoid,
    source_from_dict,
    source_to_dict,
)
from mows.physics.schema import as_points_m, check_keys, vector3

LSIP330_RADIUS_M = 0.025
LSIP330_LENGTH_M = 0.02
LSIP330_TURNS = 200
LSIP330_INDUCTANCE_H = 3.3e-3
LSIP330_LOOPS = 8  # loops in the solenoid model

PASCO_RADIUS_M = 0.105  # Methods: radius = spacing = 10.5 cm
PASCO_TURNS = 200  # EM-6723A data sheet value (not in the paper)

DEFAULT_DISTANCE_M = 0.10
DEFAULT_CURRENT_LIMIT_A = 10.0


@dataclass(frozen=True)
class CurrentCap:
    """The amplifiers' current limit: amplitudes above ``limit_a`` are refused, never clipped."""

    limit_a: float = DEFAULT_CURRENT_LIMIT_A

    def __post_init__(self) -> None:
        if not (np.isfinite(self.limit_a) and self.limit_a > 0.0):
            raise ValueError(f"limit_a must be a finite current > 0 A, got {self.limit_a!r}")

    def check(self, currents_a: ArrayLike) -> np.ndarray:
        """``currents_a`` as an array if every |I| ≤ ``limit_a``; ValueError otherwise."""
        currents = np.asarray(currents_a, dtype=float)
        if not np.all(np.isfinite(currents)):
            raise ValueError(f"coil currents must be finite, got {currents_a!r}")
        worst = float(np.max(np.abs(currents), initial=0.0))
        if worst > self.limit_a:
            raise ValueError(
                f"coil current amplitude {worst:.6g} A exceeds the cap of {self.limit_a:g} A "
                "(currents are refused, never clipped)"
            )
        return currents


def excitation_samples(duration_s: float, frequency_hz: float, sample_rate_hz: float) -> int:
    """Samples of an excitation of about ``duration_s`` that ends at a peak of the drive current
    sin(2πf·(t − t_on)), an odd number of quarter drive periods: where the probe driven into the
    housing stop is at a turning point. 0 for a zero duration.

    Why: a ring-down keeps the energy the probe has at the cut. Cut at a turning point, it
    starts at the stop; cut mid-swing, it misses the drive's work of the rest of that swing,
    about m·b·I/(kM·A) of the swing. Cut after a fixed time, the phase of the cut follows
    f·duration, and so the field: measured on the simulator for the calibration probe at
    ±2 A on the supply (f 112–137 Hz, 0.5 s), ring-downs started between 23.60° and 24.01°
    (at current zero crossings, the probe is at ≈ 6°: the stop shifts its phase from the
    free 90° lag); ending at a current peak, all start within 23.96°–24.01°. Every model that
    takes the ring-down's start from the stop (the calibration, the sweep's decomposition)
    needs that: the spread biased the calibrated f00 by −0.35 mHz (3.5σ), which the sweep's
    decomposition, f00 held, turned into a trace Gxx + Gyy 0.9 % low.
    """
    if not (duration_s >= 0.0 and frequency_hz > 0.0 and sample_rate_hz > 0.0):
        raise ValueError(
            f"duration_s = {duration_s!r} must be >= 0, frequency_hz = {frequency_hz!r} and "
            f"sample_rate_hz = {sample_rate_hz!r} > 0"
        )
    if duration_s == 0.0:
        return 0
    half_periods = max(0, round(2.0 * frequency_hz * duration_s - 0.5)) + 0.5
    return int(round(half_periods / (2.0 * frequency_hz) * sample_rate_hz))


def lsip330(center_m: ArrayLike, axis: ArrayLike) -> FieldSource:
    """One LSIP-330 excitation coil, field per ampere."""
    return solenoid(center_m, axis, LSIP330_RADIUS_M, LSIP330_LENGTH_M, LSIP330_TURNS, 1.0, LSIP330_LOOPS)


def pasco_pair(
    current_a: float, anti: bool = False, center_m: ArrayLike = (0.0, 0.0, 0.0), axis: ArrayLike = (1.0, 0.0, 0.0)
) -> FieldSource:
    """The Helmholtz setup's static-field pair (Methods: Pasco EM-6723A along x).

    Parallel (Helmholtz, ``anti`` False): uniform field; anti-parallel: gradient, B ≈ 0.
    """
    make = anti_helmholtz_pair if anti else helmholtz_pair
    return make(center_m, axis, PASCO_RADIUS_M, PASCO_TURNS, current_a)


def _in_plane(angle_rad: float) -> np.ndarray:
    return np.array([np.cos(angle_rad), np.sin(angle_rad), 0.0])


@dataclass(frozen=True, eq=False)
class CoilSetup:
    """Excitation coils and their orientation-dependent current scheme.

    Parameters
    ----------
    name : label.
    coils : field per ampere of each coil (:class:`mows.physics.field.FieldSource`).
    phases_rad : coil k carries ``amplitude_a``·sin(θ0 + phases_rad[k]).
    inductance_h : of each coil, henry (informational: the amplifiers drive the current).
    cap : the current limit.
    """

    name: str
    coils: Sequence[FieldSource]  # stored as tuples
    phases_rad: Sequence[float]
    inductance_h: float = LSIP330_INDUCTANCE_H
    cap: CurrentCap = field(default_factory=CurrentCap)

    def __post_init__(self) -> None:
        object.__setattr__(self, "coils", tuple(self.coils))
        object.__setattr__(self, "phases_rad", tuple(float(p) for p in self.phases_rad))
        if len(self.coils) != len(self.phases_rad) or not all(isinstance(c, FieldSource) for c in self.coils):
            raise ValueError(
                f"coils ({len(self.coils)}) must be field sources, one per phase ({len(self.phases_rad)} phases)"
            )

    def currents_a(self, theta0_rad: ArrayLike, amplitude_a: float) -> np.ndarray:
        """Signed current amplitude of each coil, A, shape ``theta0_rad.shape + (n_coils,)``.

        ValueError if ``amplitude_a`` is negative or above the cap.
        """
        if not (np.isfinite(amplitude_a) and amplitude_a >= 0.0):
            raise ValueError(f"amplitude_a must be a finite current ≥ 0 A, got {amplitude_a!r}")
        self.cap.check(amplitude_a)  # |amplitude·sin| ≤ amplitude: every coil's current is within the cap
        theta0 = np.asarray(theta0_rad, dtype=float)
        return amplitude_a * np.sin(theta0[..., None] + np.array(self.phases_rad))

    def coil_field_per_ampere_t(self, points_m: ArrayLike) -> np.ndarray:
        """Field of each coil per ampere at ``points_m`` (..., 3): shape (..., n_coils, 3), T/A."""
        points = as_points_m(points_m)
        return np.stack([coil.field_t(points) for coil in self.coils], axis=-2)

    def field_t(self, points_m: ArrayLike, currents_a: ArrayLike) -> np.ndarray:
        """Total coil field, T, for per-coil ``currents_a`` (..., n_coils) at ``points_m`` (..., 3)."""
        return np.einsum("...k,...ki->...i", np.asarray(currents_a, float), self.coil_field_per_ampere_t(points_m))

    def to_dict(self) -> dict:
        """Full YAML form (coils written out as field sources per ampere)."""
        return {
            "name": self.name,
            "coils": [source_to_dict(c) for c in self.coils],
            "current_phases_deg": [float(np.degrees(p)) for p in self.phases_rad],
            "inductance_h": float(self.inductance_h),
            "current_limit_a": float(self.cap.limit_a),
        }


# The two-coil setups of the paper (Methods): for each coil (position angle, field direction at
# the probe, current phase), in degrees.
PLACEMENTS_DEG = {
    # Largest spacing (Fig. 2a): coil 1 ∝ sin(θ0 + 135°), coil 2 ∝ sin(θ0 + 45°).
    "largest_spacing": ((225.0, 45.0, 135.0), (315.0, 135.0, 45.0)),
    # Helmholtz: coil 1 at −y ∝ sin(θ0 + 90°), coil 2 at −x ∝ sin(θ0).
    "helmholtz": ((270.0, 90.0, 90.0), (180.0, 180.0, 0.0)),
}


def two_coil_setup(
    name: str,
    distance_m: float = DEFAULT_DISTANCE_M,
    current_limit_a: float = DEFAULT_CURRENT_LIMIT_A,
    probe_position_m: ArrayLike = (0.0, 0.0, 0.0),
) -> CoilSetup:
    """The setup ``name`` of PLACEMENTS_DEG: coils in the x–y plane through the probe,
    ``distance_m`` from it."""
    placements = PLACEMENTS_DEG[name]
    probe = vector3("probe_position_m", probe_position_m)
    if not distance_m > LSIP330_LENGTH_M / 2:  # the probe would sit inside the coil's winding
        raise ValueError(
            f"distance_m = {distance_m:g} m puts the probe inside the coil (its half length is "
            f"{LSIP330_LENGTH_M / 2:g} m): give the distance from the probe to the coil's centre, m"
        )
    ranges.check("magnet_position_m", distance_m, "distance_m")
    coils = [
        lsip330(probe + distance_m * _in_plane(np.radians(where)), _in_plane(np.radians(along)))
        for where, along, _ in placements
    ]
    return CoilSetup(name, coils, [np.radians(phase) for _, _, phase in placements], cap=CurrentCap(current_limit_a))


largest_spacing = functools.partial(two_coil_setup, "largest_spacing")
helmholtz = functools.partial(two_coil_setup, "helmholtz")
PRESETS = {"largest_spacing": largest_spacing, "helmholtz": helmholtz}


def setup_from_dict(d: dict) -> CoilSetup:
    """A :class:`CoilSetup` from its YAML mapping (module header); ValueError on bad keys."""
    if not isinstance(d, dict):
        raise ValueError(f"a coil setup must be a mapping, got {d!r}")
    if "preset" in d:
        preset = d["preset"]
        if preset not in PRESETS:
            raise ValueError(f"coil preset {preset!r} is not one of {sorted(PRESETS)}")
        options = {k: v for k, v in d.items() if k != "preset"}
        check_keys(f"coil preset {preset!r}", options, PRESETS[preset])
        return PRESETS[preset](**options)
    check_keys("coil setup", d, _custom_setup)
    return _custom_setup(**d)


def _custom_setup(
    coils: object,
    current_phases_deg: object,
    name: str = "custom",
    inductance_h: float = LSIP330_INDUCTANCE_H,
    current_limit_a: float = DEFAULT_CURRENT_LIMIT_A,
) -> CoilSetup:
    if not isinstance(coils, (list, tuple)) or not isinstance(current_phases_deg, (list, tuple)):
        raise ValueError("coils and current_phases_deg must be lists")
    return CoilSetup(
        name,
        [source_from_dict(c) for c in coils],
        [np.radians(float(p)) for p in current_phases_deg],
        float(inductance_h),
        CurrentCap(float(current_limit_a)),
    )
