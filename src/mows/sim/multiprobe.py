"""Several probes ringing down together in one scene, each moving in the others' fields.

Probe i (its constants, pose and rotation plane: :class:`mows.physics.coupling.PlacedProbe`)
obeys the equation of motion of :mod:`mows.sim.kernel` in free flight,

    J_i·θ_i'' = −U_i'(θ_i) − 2J_i·δ_i·θ_i' + τ_i,

U_i the single-probe potential in the scene's field and gravity
(:class:`mows.physics.potential.ArcPotential`, exact on the arc), and τ_i the torque of the
other magnets at their *current* deflections: with the moment m_i(θ) = m_i·(cos θ·x' + sin θ·y')
and position r_i(θ) = pivot + l_i·m̂_i(θ), the energy −m_i(θ_i)·B_j(r_i(θ_i)) of each
neighbour's exact dipole field B_j gives

    τ_i = Σ_j [∂m_i/∂θ·B_j(r_i) + m_i·G_j(r_i)·∂r_i/∂θ],   ∂r_i/∂θ = (l_i/m_i)·∂m_i/∂θ.

So the coupling is both static (the neighbours' rest moments, :mod:`mows.physics.coupling`)
and dynamic (their swing, at their own frequencies). There is no drive and no housing stop
here: the probes start from given deflections and ring down freely.

Integrator. Classical RK4 with ``substeps`` steps per sample, as the single-probe kernel (its
phase error at 2 steps per 50 µs sample is 0.1 µHz). The pair torques are compiled (numba):
in numpy the dipole formulas' dozens of small-array operations per pair cost ~40× more
(450 µs against 12 µs per call for two probes, on a loaded machine).
tests/physics/test_multiprobe_simulation.py checks the integration against scipy's solve_ivp
and the frequencies against the coupled first-principles model.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from mows.physics.coupling import PlacedProbe, check_apart
from mows.physics.fluxgate import FluxgatePair
from mows.physics.potential import DEFAULT_NODES, ArcPotential, arc_energy_j, chebyshev_nodes_rad
from mows.physics.sources import MU0_OVER_4PI, FieldSource


def swinging_pickup_t(pair: FluxgatePair, placed: Sequence[PlacedProbe], theta_rad: np.ndarray) -> np.ndarray:
    """What both fluxgates of ``pair`` read, (n, 2) T, of the magnets ``placed`` swinging through
    the deflections ``theta_rad`` (n, N): each magnet's exact dipole field (Eq. S8) on its
    lever, summed."""
    field = np.zeros((theta_rad.shape[0], 2))
    for k, p in enumerate(placed):
        positions = p.pose.magnet_position_at(theta_rad[:, k], p.probe.lever_m)
        field += pair.pickup_t(positions, p.probe.moment_am2 * p.pose.moment_direction_at(theta_rad[:, k]))
    return field


class CoupledProbes:
    """The equation of motion of the probes ``placed`` in ``scene`` (module docstring)."""

    def __init__(self, placed: Sequence[PlacedProbe], scene: FieldSource) -> None:
        if len(placed) == 0:
            raise ValueError("a scene needs at least one probe")
        check_apart(placed)
        self.placed = tuple(placed)
        theta = chebyshev_nodes_rad()
        energy = np.array([arc_energy_j(p.probe, scene, p.pose, theta) for p in placed])
        self.potential = ArcPotential(
            [p.probe.spring_nm_per_rad for p in placed],
            [p.probe.inertia_kgm2 for p in placed],
            [p.probe.damping_per_s for p in placed],
            energy.reshape(len(placed), DEFAULT_NODES),
        )
        axes = [p.pose.axes() for p in placed]
        self._x_axis = np.array([a[0] for a in axes])  # (N, 3)
        self._y_axis = np.array([a[1] for a in axes])
        self._moment = np.array([p.probe.moment_am2 for p in placed])
        self._lever = np.array([p.probe.lever_m for p in placed])
        self._pivot = np.array([p.pose.pivot_m(p.probe.lever_m) for p in placed])
        self._inertia = np.array([p.probe.inertia_kgm2 for p in placed])
        self._two_delta = 2.0 * np.array([p.probe.damping_per_s for p in placed])

    def coupling_torque_nm(self, theta_rad: np.ndarray) -> np.ndarray:
        """(N,): τ_i, the torque of the other magnets at deflections ``theta_rad`` (module docstring)."""
        return _coupling_torques(
            np.asarray(theta_rad, float), self._moment, self._lever, self._pivot, self._x_axis, self._y_axis
        )

    def acceleration(self, theta_rad: np.ndarray, omega_rad_per_s: np.ndarray) -> np.ndarray:
        torque = self.potential.torque_nm(theta_rad) + self.coupling_torque_nm(theta_rad)
        return torque / self._inertia - self._two_delta * omega_rad_per_s

    def rhs(self) -> Callable[[float, np.ndarray], np.ndarray]:
        """rhs(t, [θ_1 … θ_N, θ'_1 … θ'_N]) for other integrators (solve_ivp)."""
        count = len(self.placed)

        def rhs(t: float, y: np.ndarray) -> np.ndarray:
            return np.concatenate([y[count:], self.acceleration(y[:count], y[count:])])

        return rhs

    def ring_down(
        self,
        start_rad: ArrayLike,
        n_samples: int,
        sample_rate_hz: float,
        substeps: int = 2,
    ) -> tuple[np.ndarray, np.ndarray]:
        """θ and θ' (n_samples, N) at the samples, from rest at deflections ``start_rad`` (N,)."""
        theta = np.array(start_rad, float)
        if theta.shape != (len(self.placed),) or not np.all(np.abs(theta) < self.potential.half_width_rad):
            raise ValueError(
                f"start_rad = {start_rad!r} must give one deflection per probe ({len(self.placed)}), "
                f"each within ±{self.potential.half_width_rad} rad"
            )
        if not (isinstance(n_samples, (int, np.integer)) and n_samples > 0 and sample_rate_hz > 0 and substeps > 0):
            raise ValueError(
                f"n_samples = {n_samples!r}, sample_rate_hz = {sample_rate_hz!r} and substeps = {substeps!r} "
                "must be positive (n_samples and substeps whole numbers)"
            )
        omega = np.zeros_like(theta)
        h = 1.0 / (sample_rate_hz * substeps)
        angles, rates = np.empty((n_samples, theta.size)), np.empty((n_samples, theta.size))
        for sample in range(n_samples):
            angles[sample], rates[sample] = theta, omega
            for _ in range(substeps):
                theta, omega = self._rk4(theta, omega, h)
        return angles, rates

    def _rk4(self, theta: np.ndarray, omega: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
        a1 = self.acceleration(theta, omega)
        a2 = self.acceleration(theta + 0.5 * h * omega, omega + 0.5 * h * a1)
        a3 = self.acceleration(theta + 0.5 * h * (omega + 0.5 * h * a1), omega + 0.5 * h * a2)
        a4 = self.acceleration(theta + h * (omega + 0.5 * h * a2), omega + h * a3)
        theta_next = theta + h * omega + h * h / 6.0 * (a1 + a2 + a3)
        omega_next = omega + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
        return theta_next, omega_next


@njit(cache=True)
def _coupling_torques(theta, moment, lever, pivot, x_axis, y_axis):
    """τ_i of the module docstring (:func:`_coupling_torques_into`), in a new array."""
    torque = np.empty(theta.size)
    _coupling_torques_into(theta, moment, lever, pivot, x_axis, y_axis, np.empty((theta.size, 6)), torque)
    return torque


@njit(cache=True)
def _coupling_torques_into(theta, moment, lever, pivot, x_axis, y_axis, axes, torque):
    """τ_i of the module docstring into ``torque``, with the dipole field of magnet j at
    r = r_i − r_j, B = μ0/(4π)·[3r(m_j·r)/r⁵ − m_j/r³], and its gradient along v = ∂r_i/∂θ,
    G·v = 3μ0/(4π r⁵)·[m_j(r·v) + r(m_j·v) + (m_j·r)v − 5(m_j·r)(r·v)r/r²]
    (the expressions of :class:`mows.physics.sources.PointDipole`). ``axes`` (N, 6) is scratch
    for each lever's direction d and turning direction u = ∂d/∂θ. Written out per component: it
    runs at every substep of the device's integration, where small arrays cost more than the sums."""
    count = theta.size
    for i in range(count):
        c, s = math.cos(theta[i]), math.sin(theta[i])
        for k in range(3):
            axes[i, k] = c * x_axis[i, k] + s * y_axis[i, k]
            axes[i, 3 + k] = -s * x_axis[i, k] + c * y_axis[i, k]
    for i in range(count):
        dx, dy, dz, ux, uy, uz = axes[i, 0], axes[i, 1], axes[i, 2], axes[i, 3], axes[i, 4], axes[i, 5]
        vx, vy, vz = lever[i] * ux, lever[i] * uy, lever[i] * uz
        rix, riy, riz = pivot[i, 0] + lever[i] * dx, pivot[i, 1] + lever[i] * dy, pivot[i, 2] + lever[i] * dz
        total = 0.0
        for j in range(count):
            if j == i:
                continue
            ex, ey, ez = axes[j, 0], axes[j, 1], axes[j, 2]
            mx, my, mz = moment[j] * ex, moment[j] * ey, moment[j] * ez
            rx = rix - (pivot[j, 0] + lever[j] * ex)
            ry = riy - (pivot[j, 1] + lever[j] * ey)
            rz = riz - (pivot[j, 2] + lever[j] * ez)
            r2 = rx * rx + ry * ry + rz * rz
            inv_r3 = r2**-1.5
            mr, rv, mv = mx * rx + my * ry + mz * rz, rx * vx + ry * vy + rz * vz, mx * vx + my * vy + mz * vz
            a, b = 3.0 * mr * inv_r3 / r2, inv_r3
            fx, fy, fz = a * rx - b * mx, a * ry - b * my, a * rz - b * mz
            g, q = 3.0 * inv_r3 / r2, 5.0 * mr * rv / r2
            gx = g * (mx * rv + rx * mv + mr * vx - q * rx)
            gy = g * (my * rv + ry * mv + mr * vy - q * ry)
            gz = g * (mz * rv + rz * mv + mr * vz - q * rz)
            # dm_i·B + m_i·(G·v), with m_i = moment_i·d and dm_i = moment_i·u; μ0/4π taken out of both
            total += ux * fx + uy * fy + uz * fz + dx * gx + dy * gy + dz * gz
        torque[i] = MU0_OVER_4PI * moment[i] * total
