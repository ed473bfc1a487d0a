"""A second truth for the lab's test data, written apart from the lab's engine.

The lab (and ``mows.lab.data.synthetic``) evaluate the probe through
:class:`mows.physics.potential.ArcPotential`: a Chebyshev series of the arc energy, Newton on the
rest angle, harmonic balance with the cycle's second harmonic, and a Gauss quadrature of the
ring-down average (:mod:`mows.physics.ringdown_average`). A bug shared by that engine and by the
tables it makes would go unseen. Nothing of it is used here; only the probe's constants
(:class:`mows.physics.probe.Probe`) and the field sources' B(r) (:mod:`mows.physics.field`).

Physics (docs/physics.md §4, the project's conventions). The probe axis x' lies at θ0 in the global
x–y plane; the lever deflects by θ in that plane; the moment points along
u(θ) = (cos(θ0 + θ), sin(θ0 + θ), 0); the magnet sits at r(θ) = l·(u(θ) − u(0)), at the origin
when θ = 0. The potential of one ring-down's probe is

    U(θ) = ½·kM·θ² + ¼·k3·θ⁴ − m·u·B(r) − ½·α·(u·B(r))² − M·l·g·u,

with B the sources' exact field at r(θ) (no expansion), the hidden terms k3 (a stiffening hinge)
and α (a moment induced along the lever) off by default, and g level (along −z: no torque).
Per row:

* the rest angle θs: ``scipy.optimize.minimize_scalar`` of U, polished by ``brentq`` on U';
* U' and U'' by central differences of the field's energy (the springs analytically; steps
  :data:`ENERGY_STEP_RAD` and :data:`STIFFNESS_STEP_RAD`, U'' to ~1e-11 of k);
* the describing function k(A) = (1/(π·A))·∫₀^{2π} U'(θs + A·cos φ)·cos φ dφ (``quad``), exact
  first-harmonic balance for a potential symmetric about θs (used for the limits);
* the ring-down as a fit sees it (:func:`ringdown`): J·θ'' + 2·J·δ·θ' + U'(θ) = 0 integrated with
  ``solve_ivp`` (DOP853, rtol 1e-9) from the turning point, over 60 periods, sampled through the
  paper's pickup g = −sin(θ0 + θ) (Eq. S11 with the sensor along y), and fitted with
  ``curve_fit`` by the estimator's model g(ε + A·e^(−δt)·cos(2πft + φ)) (its scale and offset,
  known here, held: :func:`fit_ringdown`). Its f is the frequency, its A (the swing's first
  harmonic at the first sample) the start swing.

Why the time domain: a ring-down's frequency depends on its decaying amplitude, and a
constant-frequency fit reports a weighted average (docs/model_lab.md, "The ring-down average").
At a 2° start swing in 1.8 mT along the axis the amplitude term is 1.0 mHz at the start and
0.5 mHz averaged over the ring-down: a describing function at the start swing would be 0.5 mHz
(1.5 noise σ) off.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Sequence

import numpy as np
from scipy.integrate import quad, solve_ivp
from scipy.optimize import brentq, curve_fit, minimize_scalar

from mows.physics.field import FieldSource, UniformField
from mows.physics.probe import Probe

STANDARD_GRAVITY_M_PER_S2 = 9.80665
LEVEL_GRAVITY_M_PER_S2 = (0.0, 0.0, -STANDARD_GRAVITY_M_PER_S2)
ENERGY_STEP_RAD = 1e-5  # U' of the field's energy: truncation ~1e-11, rounding ~1e-11 of the torque
STIFFNESS_STEP_RAD = 2e-3  # U'' of the field's energy, fourth order: ~1e-11 of k
REST_BOUND_RAD = 0.6  # the rest angle is sought within ±34°: far beyond any field of these tables
RINGDOWN_PERIODS = 60.0  # the paper's fit window
SAMPLES_PER_PERIOD = 32  # the pickup's signal has harmonics 1 and 2 of f: well resolved
RTOL = 1e-9  # DOP853: the frequency to ~1e-8 Hz (1e-10: ~30 % slower, the same to 9e-9 Hz)
ATOL_RAD = 1e-14


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """The field each row's probe sits in: Σ_k scale_k[row]·source_k, each source exact.

    A coil's field is its field per ampere times the row's current; a uniform field that
    differs from row to row is three unit fields with the row's components as scales
    (:meth:`uniform`).
    """

    sources: tuple[FieldSource, ...]
    scales: np.ndarray  # (sources, rows)

    @classmethod
    def of(cls, sources: Sequence[FieldSource], scales: Sequence[np.ndarray] | np.ndarray) -> Scene:
        return cls(tuple(sources), np.atleast_2d(np.asarray(scales, float)))

    @classmethod
    def uniform(cls, field_t: np.ndarray) -> Scene:
        """A uniform field per row, ``field_t`` (n, 3), global frame."""
        units = [UniformField(axis) for axis in np.eye(3)]
        return cls.of(units, np.asarray(field_t, float).T)

    def __add__(self, other: Scene) -> Scene:
        return Scene(self.sources + other.sources, np.concatenate([self.scales, other.scales]))

    def rows(self, index: int | np.ndarray) -> Scene:
        return Scene(self.sources, self.scales[:, np.atleast_1d(index)])

    @functools.cached_property
    def _constant_t(self) -> np.ndarray:
        """Σ scale·B of the uniform sources (n, 3): their field is the same at every point, so
        it is taken once (the integration's inner loop calls :meth:`field_t` ~20 000 times)."""
        origin = np.zeros(3)
        total = np.zeros((self.scales.shape[1], 3))
        for source, scale in zip(self.sources, self.scales):
            if isinstance(source, UniformField):
                total += scale[:, None] * source.field_t(origin)
        return total

    def field_t(self, points_m: np.ndarray) -> np.ndarray:
        """B at ``points_m`` (..., n, 3): row j's point in row j's field."""
        total = np.broadcast_to(self._constant_t, np.shape(points_m)).copy()
        for source, scale in zip(self.sources, self.scales):
            if not isinstance(source, UniformField):
                total += scale[:, None] * source.field_t(points_m)
        return total

    def reference(self) -> tuple[np.ndarray, np.ndarray]:
        """(B (n, 3), G (n, 3, 3)) at the undeflected magnet, the origin: the table's reference."""
        origin = np.zeros(3)
        field = sum(scale[:, None] * source.field_t(origin) for source, scale in zip(self.sources, self.scales))
        gradient = sum(
            scale[:, None, None] * source.gradient_t_per_m(origin) for source, scale in zip(self.sources, self.scales)
        )
        return np.asarray(field), np.asarray(gradient)


@dataclasses.dataclass(frozen=True, eq=False)
class Rows:
    """The probe of every row (arrays (n,)): constants, orientation, field and hidden terms.

    ``moment_am2`` and ``spring_nm_per_rad`` are per row, so that a moment that changes with
    temperature or age, or a spring warmed by a coil, is the physics of that row.
    ``induced_am2_per_t`` (α) and ``quartic_nm_per_rad3`` (k3) are the hidden energy terms;
    ``magnet_along_m`` (δ) puts the magnet δ beyond its nominal place along the lever, where the
    table's reference is given: r(θ) = l·(u(θ) − u(0)) + δ·u(θ).
    """

    probe: Probe
    theta0_rad: np.ndarray
    scene: Scene
    moment_am2: np.ndarray
    spring_nm_per_rad: np.ndarray
    induced_am2_per_t: float = 0.0
    quartic_nm_per_rad3: float = 0.0
    magnet_along_m: float = 0.0  # the magnet glued this far beyond its nominal place on the lever
    gravity_m_per_s2: tuple[float, float, float] = LEVEL_GRAVITY_M_PER_S2

    @classmethod
    def of(
        cls,
        probe: Probe,
        theta0_rad: np.ndarray,
        scene: Scene,
        moment_scale: np.ndarray | float = 0.0,
        spring_scale: np.ndarray | float = 0.0,
        **hidden: float,
    ) -> Rows:
        """Rows of ``probe`` whose moment is m·(1 + moment_scale) and spring kM·(1 + spring_scale)."""
        theta0 = np.atleast_1d(np.asarray(theta0_rad, float))
        n = len(theta0)
        moment = probe.moment_am2 * (1.0 + np.broadcast_to(np.asarray(moment_scale, float), (n,)))
        spring = probe.spring_nm_per_rad * (1.0 + np.broadcast_to(np.asarray(spring_scale, float), (n,)))
        return cls(probe, theta0, scene, moment.copy(), spring.copy(), **hidden)

    def __len__(self) -> int:
        return len(self.theta0_rad)

    def row(self, index: int) -> Rows:
        """Row ``index`` alone (a batch of one)."""
        pick = np.atleast_1d(index)
        return dataclasses.replace(
            self,
            theta0_rad=self.theta0_rad[pick],
            scene=self.scene.rows(pick),
            moment_am2=self.moment_am2[pick],
            spring_nm_per_rad=self.spring_nm_per_rad[pick],
        )


# --- the potential ------------------------------------------------------------------------------


def moment_direction(rows: Rows, theta_rad: np.ndarray) -> np.ndarray:
    """u(θ) (..., n, 3) for deflections θ (..., n)."""
    angle = rows.theta0_rad + np.asarray(theta_rad, float)
    return np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=-1)


def magnet_position_m(rows: Rows, theta_rad: np.ndarray) -> np.ndarray:
    """r(θ) = l·(u(θ) − u(0)) + δ·u(θ) (..., n, 3): the pivot lies l behind the magnet's nominal
    place, the magnet δ beyond it."""
    u = moment_direction(rows, theta_rad)
    return rows.probe.lever_m * (u - moment_direction(rows, 0.0)) + rows.magnet_along_m * u


def field_energy_j(rows: Rows, theta_rad: np.ndarray) -> np.ndarray:
    """The part of U that the field and gravity make: −m·u·B(r) − ½·α·(u·B)² − M·l·g·u.

    Written out rather than through :func:`moment_direction` and :func:`magnet_position_m`
    (the same formulas): it is the inner loop of the ring-down's integration."""
    angle = rows.theta0_rad + np.asarray(theta_rad, float)
    u = np.stack([np.cos(angle), np.sin(angle), np.zeros_like(angle)], axis=-1)
    undeflected = np.stack([np.cos(rows.theta0_rad), np.sin(rows.theta0_rad), np.zeros(len(rows))], axis=-1)
    along = (u * rows.scene.field_t(rows.probe.lever_m * (u - undeflected) + rows.magnet_along_m * u)).sum(-1)
    gravity = (
        rows.probe.magnet_mass_kg * (rows.probe.lever_m + rows.magnet_along_m) * (u @ np.asarray(rows.gravity_m_per_s2))
    )
    return -rows.moment_am2 * along - 0.5 * rows.induced_am2_per_t * along**2 - gravity


def energy_j(rows: Rows, theta_rad: np.ndarray) -> np.ndarray:
    """U(θ) (..., n), J (module docstring)."""
    theta = np.asarray(theta_rad, float)
    springs = 0.5 * rows.spring_nm_per_rad * theta**2 + 0.25 * rows.quartic_nm_per_rad3 * theta**4
    return springs + field_energy_j(rows, theta)


def torque_nm(rows: Rows, theta_rad: np.ndarray) -> np.ndarray:
    """U'(θ) (..., n): the springs analytically, the field's energy by a central difference
    (one call of the sources for both sides)."""
    theta = np.asarray(theta_rad, float)
    h = ENERGY_STEP_RAD
    sides = field_energy_j(rows, np.stack([theta + h, theta - h]))
    springs = rows.spring_nm_per_rad * theta + rows.quartic_nm_per_rad3 * theta**3
    return springs + (sides[0] - sides[1]) / (2.0 * h)


def stiffness_nm_per_rad(rows: Rows, theta_rad: np.ndarray) -> np.ndarray:
    """U''(θ) (..., n): the springs analytically, the field's energy by the fourth-order central
    second difference (−W₂ + 16·W₁ − 30·W₀ + 16·W₋₁ − W₋₂)/(12·h²). A difference of U' would
    carry the rounding of U' divided by its step (≈ 1e-8 of k); this one ~1e-11."""
    theta = np.asarray(theta_rad, float)
    h = STIFFNESS_STEP_RAD
    offsets = np.array([2.0, 1.0, 0.0, -1.0, -2.0]) * h
    energy = field_energy_j(rows, theta[None] + offsets.reshape((5,) + (1,) * theta.ndim))
    curvature = (-energy[0] + 16.0 * energy[1] - 30.0 * energy[2] + 16.0 * energy[3] - energy[4]) / (12.0 * h**2)
    return rows.spring_nm_per_rad + 3.0 * rows.quartic_nm_per_rad3 * theta**2 + curvature


def rest_angle_rad(rows: Rows) -> np.ndarray:
    """θs (n,): the minimum of U within ±:data:`REST_BOUND_RAD`, polished to U'(θs) = 0."""
    return np.array([_rest_of_one(rows.row(i)) for i in range(len(rows))])


def _rest_of_one(row: Rows) -> float:
    found = minimize_scalar(
        lambda t: float(energy_j(row, np.array([t]))[0]),
        bounds=(-REST_BOUND_RAD, REST_BOUND_RAD),
        method="bounded",
        options={"xatol": 1e-10},
    )
    slope = lambda t: float(torque_nm(row, np.array([t]))[0])  # noqa: E731
    lower, upper = found.x - 1e-4, found.x + 1e-4
    if slope(lower) * slope(upper) > 0:  # a minimum on the bound: no rest angle inside
        raise ValueError(f"no rest angle within ±{REST_BOUND_RAD} rad (minimum at {found.x:.4g})")
    return brentq(slope, lower, upper, xtol=1e-12, rtol=4 * np.finfo(float).eps)


def frequency_for_stiffness_hz(rows: Rows, stiffness: np.ndarray) -> np.ndarray:
    """√(k/J − δ²)/2π (Eq. S1), Hz."""
    omega2 = np.asarray(stiffness, float) / rows.probe.inertia_kgm2 - rows.probe.damping_per_s**2
    return np.sqrt(omega2) / (2.0 * math.pi)


def small_swing_frequency_hz(rows: Rows) -> np.ndarray:
    """The ring-down frequency as the swing goes to zero: U''(θs) in Eq. S1."""
    return frequency_for_stiffness_hz(rows, stiffness_nm_per_rad(rows, rest_angle_rad(rows)))


def describing_stiffness_nm_per_rad(rows: Rows, amplitude_rad: float, rest_rad: np.ndarray | None = None) -> np.ndarray:
    """k(A) = (1/(π·A))·∫₀^{2π} U'(θs + A·cos φ)·cos φ dφ per row (first-harmonic balance about θs).

    Exact first harmonic for a potential symmetric about θs; where the rest angle is deflected
    the cycle's mean and second harmonic shift it by O((U'''/U'')²·A²) (not used for tables)."""
    rest = rest_angle_rad(rows) if rest_rad is None else np.asarray(rest_rad, float)
    found = []
    for i in range(len(rows)):
        row, centre = rows.row(i), rest[i]

        def integrand(phi: float, row: Rows = row, centre: float = centre) -> float:
            return float(torque_nm(row, np.array([centre + amplitude_rad * math.cos(phi)]))[0]) * math.cos(phi)

        value, _ = quad(integrand, 0.0, 2.0 * math.pi, epsabs=0.0, epsrel=1e-12, limit=200)
        found.append(value / (math.pi * amplitude_rad))
    return np.array(found)


# --- the ring-down as a constant-frequency fit sees it ----------------------------------------


@dataclasses.dataclass(frozen=True)
class Ringdown:
    """Per row: the fitted frequency (Hz), the fitted swing at the first sample (rad, the
    ``amplitude_deg`` a fit reports), the rest angle θs (rad) and the fit window (s)."""

    frequency_hz: np.ndarray
    amplitude_rad: np.ndarray
    rest_rad: np.ndarray
    duration_s: np.ndarray


def ringdown(rows: Rows, swing_rad: np.ndarray | float, passes: int = 1) -> Ringdown:
    """Ring-downs whose fitted start swing (first harmonic) is ``swing_rad``, integrated and
    fitted as the estimator does (module docstring), each over 60 periods of its small-swing
    frequency.

    Each is released at rest on the side θs turns to (the nearer housing stop). The first pass
    releases it at the distance ``swing_rad`` from θs; the fit's first harmonic differs from that
    turning distance by the damping (√(1 + δ²/ω²)) and the potential's lopsidedness and
    anharmonicity: 0.0016° at 2° in 1.8 mT, 0.03° at 20°. Each further pass rescales the release
    by swing/fitted, which leaves the square of that mismatch (≤ 4e-5° at 20° after two)."""
    n = len(rows)
    rest = rest_angle_rad(rows)
    small = frequency_for_stiffness_hz(rows, stiffness_nm_per_rad(rows, rest))
    side = np.where(rest < 0.0, -1.0, 1.0)
    target = np.broadcast_to(np.asarray(swing_rad, float), (n,))
    release = target.copy()
    for _ in range(passes):
        found = _released(rows, rest, small, side * release)
        release = release * target / found.amplitude_rad
    return found


def _released(rows: Rows, rest_rad: np.ndarray, small_hz: np.ndarray, release_rad: np.ndarray) -> Ringdown:
    """The ring-downs released at rest at θs + ``release_rad`` (signed), fitted over 60 periods of
    ``small_hz`` sampled at 32 per period of the fastest row."""
    step_s = 1.0 / (SAMPLES_PER_PERIOD * small_hz.max())
    lengths = np.ceil(RINGDOWN_PERIODS / small_hz / step_s).astype(int)
    times = np.arange(lengths.max()) * step_s
    swing = integrate_swing_rad(rows, rest_rad + release_rad, times)
    fitted = [
        fit_ringdown(
            times[:length],
            rows.theta0_rad[i],
            swing[i, :length],
            (rest_rad[i], release_rad[i], small_hz[i]),
            rows.probe.damping_per_s,
        )
        for i, length in enumerate(lengths)
    ]
    frequency, amplitude = (np.array(values) for values in zip(*fitted))
    return Ringdown(frequency, amplitude, rest_rad, lengths * step_s)


def integrate_swing_rad(rows: Rows, start_rad: np.ndarray, times_s: np.ndarray) -> np.ndarray:
    """θ(t) (n, len(times)) of J·θ'' + 2J·δ·θ' + U'(θ) = 0 from rest at ``start_rad``, every row
    in one ``solve_ivp`` (the rows ring at nearly one frequency, so they share the steps well)."""
    n, inertia, damping = len(rows), rows.probe.inertia_kgm2, rows.probe.damping_per_s

    def motion(_t: float, state: np.ndarray) -> np.ndarray:
        theta, rate = state[:n], state[n:]
        return np.concatenate([rate, -2.0 * damping * rate - torque_nm(rows, theta) / inertia])

    atol = np.concatenate([np.full(n, ATOL_RAD), np.full(n, ATOL_RAD * 1e3)])
    solution = solve_ivp(
        motion,
        (0.0, float(times_s[-1])),
        np.concatenate([start_rad, np.zeros(n)]),
        method="DOP853",
        rtol=RTOL,
        atol=atol,
        t_eval=times_s,
    )
    if not solution.success:
        raise RuntimeError(f"the ring-down's integration failed: {solution.message}")
    return solution.y[:n]


def _pickup_model(
    t: np.ndarray, offset: float, amplitude: float, damping: float, frequency: float, phase: float, theta0: float
) -> np.ndarray:
    """The estimator's signal g(ε + x(t)), x = A·e^(−δt)·cos(2πft + φ), g = −sin(θ0 + ·)."""
    swing = amplitude * np.exp(-damping * t) * np.cos(2.0 * math.pi * frequency * t + phase)
    return -np.sin(theta0 + offset + swing)


def _pickup_jacobian(
    t: np.ndarray, offset: float, amplitude: float, damping: float, frequency: float, phase: float, theta0: float
) -> np.ndarray:
    """∂ signal / ∂(ε, A, δ, f, φ), shape (len(t), 5)."""
    envelope = np.exp(-damping * t)
    angle = 2.0 * math.pi * frequency * t + phase
    swing = amplitude * envelope * np.cos(angle)
    slope = -np.cos(theta0 + offset + swing)  # d signal / d swing
    turning = -amplitude * envelope * np.sin(angle)  # d swing / d phase
    columns = [np.ones_like(t), envelope * np.cos(angle), -t * swing, turning * 2.0 * math.pi * t, turning]
    return slope[:, None] * np.stack(columns, axis=-1)


def fit_ringdown(
    times_s: np.ndarray,
    theta0_rad: float,
    swing_rad: np.ndarray,
    guess: tuple[float, float, float],
    damping_per_s: float,
) -> tuple[float, float]:
    """(f, |A|) of the estimator's constant-frequency model fitted to the paper's pickup signal
    −sin(θ0 + θ(t)) of the swing θ(t) (noise-free least squares); ``guess`` = (θs, start, f).

    The pickup's scale κ and offset are known exactly here and held (κ = 1, no offset): over
    whole cycles they are orthogonal to the phase, so freeing them leaves f unchanged to first
    order, while in a noise-free fit they make the problem ill-conditioned (κ·ε against the
    offset where the signal is nearly linear in the swing)."""
    rest, start, frequency = guess
    signal = -np.sin(theta0_rad + swing_rad)
    parameters, _ = curve_fit(
        lambda t, *p: _pickup_model(t, *p, theta0=theta0_rad),
        times_s,
        signal,
        p0=[rest, start, damping_per_s, frequency, 0.0],
        jac=lambda t, *p: _pickup_jacobian(t, *p, theta0=theta0_rad),
        method="lm",
        xtol=1e-13,
        ftol=1e-13,
        gtol=1e-13,
        maxfev=400,
    )
    return float(parameters[3]), abs(float(parameters[1]))
