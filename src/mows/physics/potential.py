"""The probe's potential from first principles (docs/physics.md §4) and the frequency it implies.

For the magnet on its lever, deflected by θ in the rotation plane,

    U(θ) = ½·kM·θ² − m(θ)·B(r(θ)) − a·g·r(θ),

and the small-oscillation stiffness is k = U''(θs) at the rest angle θs where U'(θs) = 0.
The published model (Eqs. 1, 4, 5) keeps the first three terms of the expansion of this
U at θs = 0; nothing here is expanded. The frequency follows Eq. S1, f = √(k/J − δ²)/2π.

Representation. U = ½·kM·θ² + W(θ): the magnetic and gravitational part W is sampled at
Chebyshev nodes on [−w, w] (w covers the housing stop with margin) from the *actual* field,
and held as a Chebyshev series. W is analytic on that interval (l ≪ distance to any
source), so the series converges geometrically and its derivatives are exact to rounding.
One vectorised solver (:class:`ArcPotential`) then serves a single probe in any field
source (:meth:`ArcPotential.from_source`), a batch of measurements described by local field
expansions (:meth:`ArcPotential.from_local_field`, used by the model lab), and the
simulator's torque tables.

Finite amplitude. The cantilever does not swing in a parabola. For an oscillation
θ(t) = θc + A·cos φ + A2·cos 2φ (φ = ωt), the balance of the equation of motion
J·θ'' + U'(θ) = 0 in its mean, cos φ and cos 2φ parts,

    ⟨U'⟩ = 0,   J·ω²·A = 2·⟨U'·cos φ⟩,   4·J·ω²·A2 = 2·⟨U'·cos 2φ⟩,

gives the effective stiffness k(A) = J·ω² = 2·⟨U'·cos φ⟩/A, A the swing's first harmonic
(the θmax a ring-down fit reports). For a potential symmetric about its rest angle A2 = 0 and
this is first-harmonic balance (docs/physics.md §6.3: for −m·B·cos θ, k = kM + m·B·2·J1(A)/A).
Where the rest angle is deflected (a field across the probe, gravity, a gradient) the
potential is lopsided about it and the cycle's second harmonic matters: for
U' = k·x + α·x² + β·x³ about the rest angle it gives ω² = (k + (3β/4 − 5α²/(6k))·A²)/J, the
Lindstedt result (Landau & Lifshitz, Mechanics §28), where first-harmonic balance alone has
−α²/k in place of −5α²/(6k): 3–5 mHz too low for a 12°–16° swing at 3.4 mT with the rest
angle turned by 8°–12°. The harmonics beyond the second enter at O(A⁴).
The balances are solved row by row, compiled, in :mod:`mows.physics.harmonic_balance`.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from mows.physics import ringdown_average
from mows.physics.harmonic_balance import balance_rows, centre_rows
from mows.physics.pose import Pose
from mows.physics.probe import Probe
from mows.physics.sources import FieldSource

DEFAULT_NODES = 32
LOCAL_NODES = 24  # nodes of a potential built from a local field expansion (from_local_field)
DEFAULT_HALF_WIDTH_RAD = 0.75
TURNING_STEPS = 2  # fixed-point steps of first_harmonic_rad: each shrinks the error by ~(θc − θs + A2)/A ≲ 2 %
# settled_angle_rad follows U' from θ = 0 on this many steps per half-interval (1.25 mrad at
# w = 0.75: a well narrower than that is no rest a swinging probe could keep), then bisects.
SETTLE_STEPS = 600
SETTLE_BISECTIONS = 60  # a step halved 60 times: ~1e-21 rad, below the rounding of U'


def chebyshev_nodes_rad(half_width_rad: float = DEFAULT_HALF_WIDTH_RAD, n: int = DEFAULT_NODES) -> np.ndarray:
    """Chebyshev–Gauss nodes w·cos(π(k + ½)/n), k = 0 … n−1, in radians."""
    return half_width_rad * np.cos(np.pi * (np.arange(n) + 0.5) / n)


@functools.cache
def _coefficient_matrix(n: int) -> np.ndarray:
    """Matrix taking values at the n Chebyshev–Gauss nodes to series coefficients (DCT-II);
    read-only, as it is shared by every potential of n nodes."""
    j = np.arange(n)[:, None]
    k = np.arange(n)[None, :]
    m = (2.0 / n) * np.cos(np.pi * j * (k + 0.5) / n)
    m[0] *= 0.5
    m.flags.writeable = False
    return m


def _derivative(coeffs: np.ndarray, scale: float) -> np.ndarray:
    """Coefficients of d/dθ of a Chebyshev series in x = θ/w (``scale`` = 1/w), last axis."""
    rows = np.ascontiguousarray(coeffs, float).reshape(-1, np.shape(coeffs)[-1])
    return _derivative_rows(rows, scale).reshape(np.shape(coeffs))


def _clenshaw(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Σ c_j T_j(x) with coefficients on the last axis of ``coeffs`` (batch shape B) and
    x of shape B + (m,); returns B + (m,)."""
    coeffs, x = np.asarray(coeffs, float), np.asarray(x, float)
    if coeffs.ndim == x.ndim == 2 and len(coeffs) == len(x) and coeffs.flags.c_contiguous and x.flags.c_contiguous:
        # the common case, without the broadcasting's overhead
        return _clenshaw_rows(_kernel_array(coeffs), _kernel_array(x))
    shape = np.broadcast_shapes(coeffs.shape[:-1] + (1,), x.shape)
    rows = np.broadcast_to(coeffs, shape[:-1] + coeffs.shape[-1:]).reshape(-1, coeffs.shape[-1])
    points = np.broadcast_to(x, shape).reshape(-1, shape[-1])
    return _clenshaw_rows(_kernel_array(rows), _kernel_array(points)).reshape(shape)


def _kernel_array(values: ArrayLike) -> np.ndarray:
    """``values`` as the compiled kernels take them: float, C-contiguous and writable. numba
    compiles a kernel once per argument layout, read-only included (what np.broadcast_to gives):
    one layout, one compilation, which the precompiled cache holds."""
    return np.require(values, float, ["C", "W"])


# Compiled (numba): the lab evaluates small batches tens of thousands of times per analysis, where
# a loop over the 32 coefficients in numpy spent its time in per-operation overhead. Same
# arithmetic, in the same order, as the recurrences written out in numpy.
@njit(cache=True)
def _derivative_rows(coeffs: np.ndarray, scale: float) -> np.ndarray:
    out = np.zeros_like(coeffs)
    n = coeffs.shape[1]
    for r in range(coeffs.shape[0]):
        for j in range(n - 1, 0, -1):
            out[r, j - 1] = 2.0 * j * coeffs[r, j] + (out[r, j + 1] if j + 1 < n else 0.0)
        out[r, 0] *= 0.5
    return out * scale


@njit(cache=True)
def _clenshaw_rows(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    out = np.empty_like(x)
    b1, b2 = np.empty(x.shape[1]), np.empty(x.shape[1])
    for r in range(x.shape[0]):
        b1[:] = 0.0
        b2[:] = 0.0
        # Points innermost, so that the recurrence runs over them in vector registers.
        for j in range(coeffs.shape[1] - 1, 0, -1):
            for i in range(x.shape[1]):
                b1[i], b2[i] = 2.0 * x[r, i] * b1[i] - b2[i] + coeffs[r, j], b1[i]
        for i in range(x.shape[1]):
            out[r, i] = x[r, i] * b1[i] - b2[i] + coeffs[r, 0]
    return out


class ArcPotential:
    """U(θ) = ½·kM·θ² + W(θ) for a batch of probes, W a Chebyshev series on [−w, w].

    Parameters
    ----------
    spring_nm_per_rad : kM, shape B (the batch shape) or broadcastable to it.
    inertia_kgm2, damping_per_s : J and δ of Eq. S1 (broadcastable to B).
    energy_samples_j : W at :func:`chebyshev_nodes_rad` (``half_width_rad``, n), shape B + (n,).
    """

    def __init__(
        self,
        spring_nm_per_rad: ArrayLike,
        inertia_kgm2: ArrayLike,
        damping_per_s: ArrayLike,
        energy_samples_j: ArrayLike,
        half_width_rad: float = DEFAULT_HALF_WIDTH_RAD,
    ) -> None:
        samples = np.asarray(energy_samples_j, dtype=float)
        self.half_width_rad = float(half_width_rad)
        self.batch_shape = samples.shape[:-1]
        self.spring_nm_per_rad = np.broadcast_to(np.asarray(spring_nm_per_rad, float), self.batch_shape)
        self.inertia_kgm2 = np.broadcast_to(np.asarray(inertia_kgm2, float), self.batch_shape)
        self.damping_per_s = np.broadcast_to(np.asarray(damping_per_s, float), self.batch_shape)
        self.coeffs = samples @ _coefficient_matrix(samples.shape[-1]).T
        self.d1 = _derivative(self.coeffs, 1.0 / self.half_width_rad)
        self.d2 = _derivative(self.d1, 1.0 / self.half_width_rad)

    # --- U and its derivatives, θ of shape B + (m,) or B -----------------------------------
    def _eval(self, coeffs: np.ndarray, theta_rad: ArrayLike) -> np.ndarray:
        theta = np.asarray(theta_rad, dtype=float)
        per_row = theta.shape == self.batch_shape
        t = theta[..., None] if per_row else theta
        value = _clenshaw(coeffs, t / self.half_width_rad)
        return value[..., 0] if per_row else value

    def _spring(self, theta: ArrayLike) -> np.ndarray:
        kM = self.spring_nm_per_rad
        return kM if np.ndim(theta) == len(self.batch_shape) else kM[..., None]

    def energy_j(self, theta_rad: ArrayLike) -> np.ndarray:
        return 0.5 * self._spring(theta_rad) * np.square(theta_rad) + self._eval(self.coeffs, theta_rad)

    def torque_nm(self, theta_rad: ArrayLike) -> np.ndarray:
        """Restoring torque −dU/dθ, N·m."""
        return -(self._spring(theta_rad) * theta_rad + self._eval(self.d1, theta_rad))

    def stiffness_nm_per_rad(self, theta_rad: ArrayLike | None = None) -> np.ndarray:
        """U''(θ), N·m/rad; at the exact rest angle by default."""
        theta = self.rest_angle_rad() if theta_rad is None else theta_rad
        return self._spring(theta) + self._eval(self.d2, theta)

    # --- equilibrium, finite amplitude and frequency ----------------------------------------
    def rest_angle_rad(self) -> np.ndarray:
        """Exact rest angle θs (U'(θs) = 0, U''(θs) > 0) nearest 0; NaN where none is stable."""
        return self._rest_rad.copy()

    def settled_angle_rad(self) -> np.ndarray:
        """Where the probe at rest sits: the minimum of U that the probe falls into from θ = 0,
        which is the rest angle θs where there is one (:meth:`rest_angle_rad`). Beyond spring
        cancellation (U''(0) < 0) it is a buckled rest off zero: the minimum on the downhill
        side of 0 (the positive side on a symmetric top, whose two wells are alike), where U'
        changes sign from − to + along the fall. NaN where U falls to the interval's edge (the
        probe would lie on its stop, which U does not hold)."""
        step = self.half_width_rad / SETTLE_STEPS
        side = np.where(self.torque_nm(np.zeros(self.batch_shape)) < 0.0, -1.0, 1.0)  # downhill from 0
        path = side[..., None] * (step * np.arange(SETTLE_STEPS))  # B + (m,), inside the interval
        risen = -side[..., None] * self.torque_nm(path) >= 0.0  # U' has turned against the fall
        risen[..., 0] = False
        index = np.argmax(risen, axis=-1)[..., None]
        low = np.take_along_axis(path, np.maximum(index - 1, 0), axis=-1)[..., 0]
        high = np.take_along_axis(path, index, axis=-1)[..., 0]
        rest = self.rest_angle_rad()
        in_well = (rest - low) * (rest - high) <= 0.0  # Newton's θs lies in the same step: it is this minimum
        if not np.all(in_well):
            rest = np.where(in_well, rest, self._bisected(side, low, high))
        return np.where(risen.any(axis=-1), rest, np.nan)

    def _bisected(self, side: np.ndarray, low: np.ndarray, high: np.ndarray) -> np.ndarray:
        """The zero of U' between ``low``, where it is against ``side``, and ``high``, where it is not."""
        for _ in range(SETTLE_BISECTIONS):
            middle = 0.5 * (low + high)
            turned = -side * self.torque_nm(middle) >= 0.0
            low, high = np.where(turned, low, middle), np.where(turned, middle, high)
        return 0.5 * (low + high)

    @functools.cached_property
    def _rest_rad(self) -> np.ndarray:
        """θs, solved once: the balances at every amplitude start from it."""
        return self.cycle_centre_rad(np.zeros(self.batch_shape))

    def cycle_centre_rad(self, amplitude_rad: ArrayLike) -> np.ndarray:
        """Centre θc of an oscillation of amplitude A from the DC balance ⟨U'(θc + A·cos φ)⟩ = 0.

        Solved by Newton's method from θ = 0; NaN where it does not converge inside the
        interval or where the balance is unstable (⟨U''⟩ ≤ 0, beyond spring cancellation).
        """
        amplitude = np.broadcast_to(np.asarray(amplitude_rad, float), self.batch_shape)
        centres = centre_rows(*self._rows(), _kernel_array(amplitude.ravel()), self.half_width_rad)
        return centres.reshape(self.batch_shape)

    def _rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(U' coefficients, U'' coefficients, kM) with the batch flattened to rows, for the kernels."""
        count = self.d1.shape[-1]
        return (
            _kernel_array(self.d1.reshape(-1, count)),
            _kernel_array(self.d2.reshape(-1, count)),
            _kernel_array(np.ravel(self.spring_nm_per_rad)),
        )

    def effective_stiffness_nm_per_rad(self, amplitude_rad: ArrayLike = 0.0) -> np.ndarray:
        """Harmonic-balance stiffness k(A) with the cycle's second harmonic (module docstring);
        U''(θs) at A = 0; NaN where the balance is unstable or the swing leaves the interval.
        ``amplitude_rad`` broadcasts to the batch shape B, or is B + (q,): q amplitudes of each
        element (a ring-down's amplitude nodes), which share its rest angle and coefficients."""
        return self._balance(amplitude_rad)[0]

    def first_harmonic_rad(self, turning_rad: ArrayLike) -> np.ndarray:
        """The first harmonic A of the free swing that turns at θs + ``turning_rad`` (signed).

        A ring-down released at the housing stop turns there; the fit reports the swing's first
        harmonic, which in a lopsided potential differs from the turning point's distance to the
        rest angle by the cycle's mean and second harmonic: at φ = 0 or π the swing is at
        θc + A2 ± A, so A = |turning| − s·(θc − θs + A2) on the side s of the turning point.
        """
        turning = np.broadcast_to(np.asarray(turning_rad, float), self.batch_shape)
        side, distance = np.sign(turning), np.abs(turning)
        rest = self.rest_angle_rad()
        amplitude = distance
        for _ in range(TURNING_STEPS):
            _, mean, second = self._balance(amplitude)
            amplitude = distance - side * (mean - rest + second)
        return amplitude

    def start_swing_rad(self, stop_rad: ArrayLike) -> np.ndarray:
        """θmax of a ring-down released at the housing stop: the first harmonic of the swing that
        turns at the nearer stop, θstop − |θs| from the rest angle θs on the side θs turns to
        (:func:`mows.physics.ringdown_average.swing_from_stop_rad` at the release); NaN where
        the stop lies inside the deflection (no free swing) or the potential has no stable rest angle."""
        rest = self.rest_angle_rad()
        distance = ringdown_average.swing_from_stop_rad(np.asarray(stop_rad, float), rest)
        return self.first_harmonic_rad(np.where(rest < 0.0, -distance, distance))

    def _balance(self, amplitude_rad: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(k(A), θc, A2) of the harmonic balance with the second harmonic (module docstring),
        amplitudes of shape B or B + (q,) (:meth:`effective_stiffness_nm_per_rad`)."""
        amplitude = np.asarray(amplitude_rad, float)
        nodes = amplitude.shape[-1] if amplitude.ndim > len(self.batch_shape) else 1
        shape = self.batch_shape + amplitude.shape[-1:] if amplitude.ndim > len(self.batch_shape) else self.batch_shape
        amplitude = _kernel_array(np.broadcast_to(amplitude, shape)).reshape(-1, nodes)
        found = balance_rows(*self._rows(), self._rest_rad.ravel(), amplitude, self.half_width_rad)
        return tuple(values.reshape(shape) for values in found)  # type: ignore[return-value]

    def frequency_hz(self, amplitude_rad: ArrayLike = 0.0) -> np.ndarray:
        """Ring-down frequency √(k(A)/J − δ²)/2π, Hz (Eq. S1 with the exact k); NaN if unstable."""
        omega2 = self.effective_stiffness_nm_per_rad(amplitude_rad) / self.inertia_kgm2 - self.damping_per_s**2
        return np.sqrt(np.where(omega2 > 0, omega2, np.nan)) / (2.0 * math.pi)

    # --- builders ---------------------------------------------------------------------------
    @classmethod
    def from_source(
        cls,
        probe: Probe,
        source: FieldSource,
        pose: Pose,
        temperature_k: float | None = None,
        nodes: int = DEFAULT_NODES,
        half_width_rad: float = DEFAULT_HALF_WIDTH_RAD,
    ) -> ArcPotential:
        """The potential of ``probe`` placed at ``pose`` in the field of ``source``."""
        theta = chebyshev_nodes_rad(half_width_rad, nodes)
        energy = arc_energy_j(probe, source, pose, theta)
        spring = probe.spring_nm_per_rad if temperature_k is None else probe.spring_at(temperature_k)
        return cls(spring, probe.inertia_kgm2, probe.damping_per_s, energy, half_width_rad)

    @classmethod
    def from_local_field(
        cls,
        probe: Probe,
        field_t: ArrayLike,
        gradient_t_per_m: ArrayLike | None = None,
        hessian_t_per_m2: ArrayLike | None = None,
        gravity_m_per_s2: ArrayLike | None = None,
        spring_nm_per_rad: ArrayLike | None = None,
        lever_m: ArrayLike | None = None,
        damping_per_s: ArrayLike | None = None,
        energy_j: ArrayLike | None = None,
        magnet_offset_m: ArrayLike | None = None,
        nodes: int = LOCAL_NODES,
        half_width_rad: float = DEFAULT_HALF_WIDTH_RAD,
    ) -> ArcPotential:
        """Batch potential from the field's Taylor expansion at the magnet's rest position.

        All vectors and tensors are in the **probe frame** (x', y', z'), batch-shaped:
        field (B, 3), gradient (B, 3, 3), Hessian (B, 3, 3, 3), gravity (B, 3). Each batch
        element is one measurement. The magnet moves by δr = l·(cos θ − 1, sin θ, 0), so
        B(r(θ)) = B + G·δr + ½·H:δr δr exactly for a field that is quadratic over the arc.
        ``spring_nm_per_rad``, ``lever_m`` and ``damping_per_s`` override the probe's
        (per-row spring for thermal drift; free lever or damping in a fit). ``energy_j`` (B, nodes)
        is energy of any other origin at the nodes (:func:`chebyshev_nodes_rad`), added to W.
        ``magnet_offset_m`` (B, 3) puts the magnet off the lever's axis (:func:`arc_displacement_m`;
        the expansion is still at its rest position); the moment stays along the lever.
        """
        theta = chebyshev_nodes_rad(half_width_rad, nodes)
        lever = probe.lever_m if lever_m is None else np.asarray(lever_m, float)
        field = np.asarray(field_t, float)
        u = np.stack([np.cos(theta), np.sin(theta), np.zeros_like(theta)], -1)  # (n, 3)
        dr = arc_displacement_m(theta, lever, magnet_offset_m)
        b_along_arc = np.broadcast_to(field[..., None, :], np.broadcast_shapes(field[..., None, :].shape, dr.shape))
        # G·δr and ½·H:δr δr as batched matrix products (einsum's broadcast loops are ~5× slower).
        if gradient_t_per_m is not None:
            b_along_arc = b_along_arc + dr @ np.swapaxes(np.asarray(gradient_t_per_m, float), -1, -2)
        if hessian_t_per_m2 is not None:
            hessian = np.asarray(hessian_t_per_m2, float)
            dr_dr = (dr[..., :, None] * dr[..., None, :]).reshape(dr.shape[:-1] + (9,))
            b_along_arc = b_along_arc + 0.5 * (dr_dr @ np.swapaxes(hessian.reshape(hessian.shape[:-2] + (9,)), -1, -2))
        energy = -probe.moment_am2 * np.einsum("nj,...nj->...n", u, b_along_arc)
        if gravity_m_per_s2 is not None:
            weight = probe.magnet_mass_kg * np.asarray(gravity_m_per_s2, float)
            energy = energy - np.einsum("nj,...j->...n", u, weight) * np.asarray(lever)[..., None]
            if magnet_offset_m is not None:  # the offset turns with the lever: its height changes too
                energy = energy - np.einsum("...nj,...j->...n", _turned(theta, magnet_offset_m), weight)
        if energy_j is not None:
            energy = energy + np.asarray(energy_j, float)
        spring = probe.spring_nm_per_rad if spring_nm_per_rad is None else spring_nm_per_rad
        damping = probe.damping_per_s if damping_per_s is None else damping_per_s
        return cls(spring, probe.inertia_kgm2, damping, energy, half_width_rad)


def arc_displacement_m(
    theta_rad: np.ndarray, lever_m: ArrayLike, magnet_offset_m: ArrayLike | None = None
) -> np.ndarray:
    """δr(θ), the magnet's displacement from its rest position at deflections θ (n,), probe
    frame, m: shape (n, 3), or B + (n, 3) for a per-row lever or offset.

    The magnet sits at (l, 0, 0) + ``magnet_offset_m`` (along, across, normal) from the pivot in
    the lever's own frame, which turns with θ about z': with the arm r = (l + a, c, n),

        δr(θ) = Rz(θ)·r − r.
    """
    unit = np.stack([np.cos(theta_rad) - 1.0, np.sin(theta_rad), np.zeros_like(theta_rad)], -1)
    dr: np.ndarray = np.multiply.outer(np.asarray(lever_m), unit) if np.ndim(lever_m) else np.asarray(lever_m) * unit
    if magnet_offset_m is not None:
        dr = dr + _turned(theta_rad, magnet_offset_m) - np.asarray(magnet_offset_m, float)[..., None, :]
    return dr


def _turned(theta_rad: np.ndarray, offset_m: ArrayLike) -> np.ndarray:
    """Rz(θ)·offset, offsets B + (3,) at deflections θ (n,): B + (n, 3)."""
    c, s, zero, one = np.cos(theta_rad), np.sin(theta_rad), np.zeros_like(theta_rad), np.ones_like(theta_rad)
    turns = np.stack([c, -s, zero, s, c, zero, zero, zero, one], -1).reshape(-1, 3, 3)
    return np.einsum("nij,...j->...ni", turns, np.asarray(offset_m, float))


def arc_energy_j(probe: Probe, source: FieldSource, pose: Pose, theta_rad: ArrayLike) -> np.ndarray:
    """W(θ) = −m(θ)·B(r(θ)) − a·g·(r(θ) − pivot), J, at deflections ``theta_rad`` (PHYSICS §4)."""
    direction = pose.moment_direction_at(theta_rad)
    position = pose.magnet_position_at(theta_rad, probe.lever_m)
    magnetic = -probe.moment_am2 * np.einsum("...j,...j->...", direction, source.field_t(position))
    gravity = -probe.magnet_mass_kg * probe.lever_m * (direction @ np.asarray(pose.gravity_m_per_s2, float))
    return magnetic + gravity
