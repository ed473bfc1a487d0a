"""An eight-coil magnetic navigation system, the truth a workspace map is measured in.

Built like the systems that steer magnetic catheters and capsules (OctoMag, Navion): eight
cored electromagnets on a hemisphere around the workspace, their axes through its centre, four
at 45° below the horizontal plane of their tips' centre and four in it, between them. Each coil
is a finite winding, not a point: ``LAYERS`` radial layers × ``SLICES`` loops along its length,
every loop an exact current loop (Biot–Savart, :class:`mows.physics.loops.CurrentLoop`) with
its own winding error (position, tilt, radius), and a soft-iron core whose magnetisation is a
second source model: a chain of point dipoles along the core (:class:`PointDipole`), its moment
proportional to the coil's current. No term of this field is a solid harmonic about the
workspace centre: the model fitted to it (:mod:`mows.workspace`) is not the code that made it.

The currents are scaled so that the field at the centre has ``centre_field_t`` in magnitude;
in the default design the gradient over a 5 cm workspace stays within the probe's ±50 mT/m.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.physics.field import CurrentLoop, FieldSource, PointDipole, SumSource

LAYERS = 3
SLICES = 6
CORE_DIPOLES = 5


@dataclasses.dataclass(frozen=True)
class CoilDesign:
    """One electromagnet: winding between ``inner_radius_m`` and ``outer_radius_m`` over
    ``length_m``, ``turns`` in all; its tip (the winding's end nearer the workspace) at
    ``tip_distance_m`` from the centre; the core's moment per ampere ``core_am2_per_a`` (the
    iron's magnetisation times its volume, linear below saturation)."""

    inner_radius_m: float = 0.02
    outer_radius_m: float = 0.04
    length_m: float = 0.08
    turns: float = 400.0
    tip_distance_m: float = 0.12
    core_am2_per_a: float = 4.0


@dataclasses.dataclass(frozen=True)
class WindingErrors:
    """Standard deviations of each loop's errors: position (m), tilt of its axis (rad), radius
    (fraction); of each core's moment (fraction) and of each coil's current (fraction)."""

    position_m: float = 0.5e-3
    tilt_rad: float = math.radians(0.5)
    radius: float = 0.01
    core_moment: float = 0.05
    current: float = 0.002


def coil_axes() -> np.ndarray:
    """(8, 3): unit vectors from the centre to each coil, a hemisphere below the centre."""
    axes = []
    for k in range(4):
        azimuth = k * math.pi / 2
        axes.append((math.cos(azimuth), math.sin(azimuth), 0.0))
        azimuth += math.pi / 4
        elevation = -math.pi / 4
        axes.append(
            (math.cos(elevation) * math.cos(azimuth), math.cos(elevation) * math.sin(azimuth), math.sin(elevation))
        )
    return np.array(axes)


def _perpendicular(axis: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    helper = np.array([0.0, 0.0, 1.0]) if abs(axis[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    first = np.cross(axis, helper)
    first /= np.linalg.norm(first)
    return first, np.cross(axis, first)


def _coil(design: CoilDesign, axis: np.ndarray, current_a: float, errors: WindingErrors, rng) -> list[FieldSource]:
    """One electromagnet's loops and core dipoles; its field points along −axis (towards the
    centre) for a positive current."""
    u, v = _perpendicular(axis)
    sources: list[FieldSource] = []
    radii = design.inner_radius_m + (np.arange(LAYERS) + 0.5) / LAYERS * (design.outer_radius_m - design.inner_radius_m)
    depths = design.tip_distance_m + (np.arange(SLICES) + 0.5) / SLICES * design.length_m
    turns = design.turns / (LAYERS * SLICES)
    for radius in radii:
        for depth in depths:
            tilt = rng.normal(0.0, errors.tilt_rad, 2)
            loop_axis = -axis + tilt[0] * u + tilt[1] * v
            centre = depth * axis + rng.normal(0.0, errors.position_m, 3)
            loop_radius = radius * (1.0 + rng.normal(0.0, errors.radius))
            sources.append(CurrentLoop(centre, loop_axis / np.linalg.norm(loop_axis), loop_radius, turns, current_a))
    core_moment = design.core_am2_per_a * current_a * (1.0 + rng.normal(0.0, errors.core_moment)) / CORE_DIPOLES
    for depth in design.tip_distance_m + (np.arange(CORE_DIPOLES) + 0.5) / CORE_DIPOLES * design.length_m:
        sources.append(PointDipole(-core_moment * axis, depth * axis))
    return sources


def navigation_system(
    centre_field_t: float = 3e-3,
    seed: int = 0,
    design: CoilDesign = CoilDesign(),
    errors: WindingErrors = WindingErrors(),
) -> SumSource:
    """The eight coils with winding errors drawn from ``seed``, their currents a fixed pattern
    of signs and sizes (one field configuration, as a map is measured in), scaled to
    ``centre_field_t`` at the centre."""
    rng = np.random.default_rng(seed)
    pattern = np.array([1.0, -0.6, 0.8, 0.3, -0.9, 0.5, -0.4, 0.7])
    currents = pattern * (1.0 + rng.normal(0.0, errors.current, pattern.size))
    sources: list[FieldSource] = []
    for axis, current in zip(coil_axes(), currents):
        sources.extend(_coil(design, axis, float(current), errors, rng))
    unscaled = SumSource(sources)
    magnitude = float(np.linalg.norm(unscaled.field_t(np.zeros(3))))
    return unscaled.scaled(centre_field_t / magnitude)
