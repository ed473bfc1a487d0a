"""Where the probe sits and how it is turned.

The rotation plane is spanned by unit vectors ``e1`` and ``e2``; the orientation θ0 is counted
from e1 towards e2. In the probe frame x' = cos θ0·e1 + sin θ0·e2 is the moment at rest,
y' = −sin θ0·e1 + cos θ0·e2, z' = e1 × e2. A deflection θ (θt in the paper, Eq. S2) turns
the lever in the plane about the pivot, so the magnet sits at pivot + l·(cos θ·x' + sin θ·y')
and its moment points along (cos θ·x' + sin θ·y') (Eq. S7).

The stage turns the probe about an axis through the magnet's rest position, so
"the field at the probe" is the field at ``magnet_position_m`` for every θ0, and the pivot
is at magnet_position − l·x'.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

STANDARD_GRAVITY_M_PER_S2 = 9.80665


def probe_axes(theta0_rad: ArrayLike) -> np.ndarray:
    """Rows x', y', z' of the probe frame in a rotation plane that is the global x–y plane, shape
    θ0.shape + (3, 3): ``axes @ v`` is v in the probe frame."""
    theta = np.asarray(theta0_rad, float)
    c, s = np.cos(theta), np.sin(theta)
    axes = np.zeros(theta.shape + (3, 3))
    axes[..., 0, 0], axes[..., 0, 1], axes[..., 1, 0], axes[..., 1, 1], axes[..., 2, 2] = c, s, -s, c, 1.0
    return axes


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b of two 3-vectors, as ``np.cross`` computes it (the same products and differences):
    the simulator asks for a pose's axes at every block it reads, and ``np.cross``'s
    general-shape handling cost more than the rest of the block's geometry."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


@dataclasses.dataclass(frozen=True)
class Pose:
    """Placement of the probe. Vectors are global-frame, SI units."""

    magnet_position_m: tuple = (0.0, 0.0, 0.0)
    theta0_rad: float = 0.0
    plane_e1: tuple = (1.0, 0.0, 0.0)
    plane_e2: tuple = (0.0, 1.0, 0.0)
    gravity_m_per_s2: tuple = (0.0, 0.0, -STANDARD_GRAVITY_M_PER_S2)

    def __post_init__(self) -> None:
        e1, e2 = np.asarray(self.plane_e1, float), np.asarray(self.plane_e2, float)
        if abs(np.linalg.norm(e1) - 1) > 1e-9 or abs(np.linalg.norm(e2) - 1) > 1e-9 or abs(e1 @ e2) > 1e-9:
            raise ValueError(
                f"plane_e1 = {self.plane_e1} and plane_e2 = {self.plane_e2} must be "
                "orthonormal (unit length, perpendicular)"
            )
        if not math.isfinite(self.theta0_rad):
            raise ValueError(f"theta0_rad = {self.theta0_rad} must be finite")

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Probe axes (x', y', z') as three global unit vectors."""
        e1, e2 = np.asarray(self.plane_e1, float), np.asarray(self.plane_e2, float)
        c, s = math.cos(self.theta0_rad), math.sin(self.theta0_rad)
        return c * e1 + s * e2, -s * e1 + c * e2, _cross(e1, e2)

    def with_theta0(self, theta0_rad: float) -> Pose:
        return dataclasses.replace(self, theta0_rad=float(theta0_rad))

    def pivot_m(self, lever_m: float) -> np.ndarray:
        return np.asarray(self.magnet_position_m, float) - lever_m * self.axes()[0]

    def moment_direction_at(self, theta_rad: ArrayLike) -> np.ndarray:
        """Unit moment direction at deflection θ, shape θ.shape + (3,)."""
        x_axis, y_axis, _ = self.axes()
        theta = np.asarray(theta_rad, float)[..., None]
        return np.cos(theta) * x_axis + np.sin(theta) * y_axis

    def magnet_position_at(self, theta_rad: ArrayLike, lever_m: float) -> np.ndarray:
        """Magnet position at deflection θ, shape θ.shape + (3,)."""
        return self.pivot_m(lever_m) + lever_m * self.moment_direction_at(theta_rad)

    @classmethod
    def tilted(cls, tilt_rad: float, tilt_axis_rad: float = 0.0, **kwargs: Any) -> Pose:
        """A horizontal x–y rotation plane tilted by ``tilt_rad`` about the in-plane axis at
        angle ``tilt_axis_rad`` from x: expressed, in the plane's own frame, as gravity acquiring
        an in-plane component g·sin(tilt) perpendicular to the tilt axis."""
        g = STANDARD_GRAVITY_M_PER_S2
        down_in_plane = np.array([-math.sin(tilt_axis_rad), math.cos(tilt_axis_rad), 0.0])
        gravity = g * math.sin(tilt_rad) * down_in_plane + np.array([0.0, 0.0, -g * math.cos(tilt_rad)])
        return cls(gravity_m_per_s2=tuple(gravity), **kwargs)
