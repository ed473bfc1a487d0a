"""Time-domain simulation of the measurement cycle (PHYSICS.md §1, §4), sample by sample like the device.

Equation of motion. The deflection θ (θt of Eq. S2) obeys

    J·θ'' = −U'(θ, t) − 2J·δ·θ' − Σ_k I_k(t)·W_k'(θ) + τ_stop(θ, θ'),

with U(θ, t) = ½·kM(T(t))·θ² + W(θ) the full potential of PHYSICS.md §4 in the environment
field at the current pose (gravity included, nothing expanded: :class:`mows.physics.potential.ArcPotential`),
W_k(θ) = −m(θ)·B_k(r(θ)) the energy of the magnet in coil k's field per ampere along the same
arc, and I_k(t) = A_k·sin(2πf·(t − t_on)) the drive. Free, δ gives the envelope e^(−δt) and the
frequency √(k/J − δ²)/2π of Eqs. S1, S2. kM follows the temperature T(t) = T0 + rate·t.
All derivatives W', W_k' are Chebyshev series taken from ArcPotential (``d1``), so the torque
is exact to rounding on the whole arc.

Housing stop. At |θ| > θstop the housing pushes back as a stiff spring–dashpot contact,
k_c·p + c·ṗ with penetration p = |θ| − θstop, stiffness k_c = ``stiffness_ratio``·kM (1000 by
default: contact ≈ 140 µs, penetration ≈ 0.5° at the impact speeds of a 2 A drive) and
damping c = 2ζ·√(k_c·J), ζ = −ln e/√(π² + ln² e), which gives a linear contact the
coefficient of restitution e. The contact ends when its force would pull (no adhesion), so
the measured restitution is a little above e (0.56 for e = 0.5). A driven probe hammers
against the stop and rings down from there (≈ 24°, the paper's calibrated θmax) when the
coils switch off.

Integrator. Classical RK4 with a fixed step: ``substeps`` steps per sample in free flight
and ``contact_substeps`` in every sample in which the stop can be reached. The contact force
jumps at the touch (c·ṗ) and has a kink at the release, so every step that crosses one of
these events is cut there: the event instant is found by Newton's method on the step
fraction, and RK4 keeps its fourth order through impacts (trajectories with 16 and 128
contact sub-steps agree to 1e-7 rad). RK4's phase error is (ωh)⁴/120 per radian: at 2 steps
per 50 µs sample and 112 Hz, 8e-10 relative, i.e. 0.1 µHz, far below the 0.01 mHz the
estimator resolves; its energy error, (ωh)⁶/144 per step, acts like a damping of 1e-8 1/s
(tests/physics/test_simulator.py measures both). The kernel is compiled by numba once per
machine (``cache=True``, ≈ 1 s); later processes load it from the cache.

Fluxgates. At every sample: the exact dipole field of the magnet at its actual position with
its actual moment (:meth:`mows.physics.fluxgate.FluxgatePair.pickup_t`), plus the environment field,
plus each coil's field × its current (they saturate the sensors during excitation, as in the
paper), noise (:class:`NoiseStream`), then offset compensation, ±range clipping and
quantisation (:meth:`mows.physics.fluxgate.FluxgatePair.digitise`). The magnet is a point dipole: a
1 mm cylinder's next multipole is ~(0.5 mm/6 cm)² ≈ 1e-4 of its field at the sensors.

Device clock. Sample i is taken at t = i/fs; :meth:`SimulatedDevice.read` returns the next n
samples and leaves the probe moving, so consecutive reads form one continuous stream
(noise included) and a read of 2n equals two reads of n.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit
from scipy import signal as sp_signal

from mows.physics.potential import DEFAULT_HALF_WIDTH_RAD, ArcPotential
from mows.records.samples import SampleBlock
from mows.records.stamps import NS_PER_S

TWO_PI = 2.0 * math.pi

# The Chebyshev interval covers the stop with room for the contact's penetration.
INTERVAL_OVER_STOP = 1.5
# Chebyshev terms below this fraction of kM·w (N·m) are dropped from the kernel's series.
SERIES_TOLERANCE = 1e-15
# In a sample where |θ| + 2|θ'|·Δt + this margin reaches θstop the contact sub-steps are used.
CONTACT_MARGIN_RAD = 1e-3

# 1/f noise: pole–zero pairs spaced 2 per decade from PINK_LOW_HZ up (module NoiseStream).
PINK_LOW_HZ = 0.01
PINK_POLES_PER_DECADE = 2

# Parameter vector of the kernel (one array keeps numba's signature short).
P_INV_INERTIA, P_TWO_DELTA, P_SPRING0, P_SPRING_RATE, P_INV_WIDTH, P_STOP, P_K_STOP, P_C_STOP = range(8)


# --- the numba kernel ----------------------------------------------------------------------
# Contact mode of the housing stop: FREE, or the side (+1, −1) of the stop in contact.
FREE = 0.0
MAX_EVENTS_PER_STEP = 4
EVENT_NEWTON_STEPS = 4


@njit(cache=True)
def acceleration(theta, omega, t, mode, params, env, drive, drive_omega, drive_t0):
    """θ'' at (θ, θ', t) in contact ``mode``: the equation of motion of the module docstring.

    ``env`` and ``drive`` hold Chebyshev coefficients of W' and Σ_k A_k·W_k' in x = θ/w
    (``drive`` is empty when the coils are off). In contact with side s = ``mode`` the stop
    pushes back with k_c·p + c·ṗ, p = s·θ − θstop.
    """
    x = theta * params[P_INV_WIDTH]
    t_prev, t_cur = 1.0, x
    s_env = env[0] + env[1] * x
    n_drive = drive.shape[0]
    s_drive = drive[0] + drive[1] * x if n_drive > 0 else 0.0
    for j in range(2, max(env.shape[0], n_drive)):
        t_prev, t_cur = t_cur, 2.0 * x * t_cur - t_prev
        if j < env.shape[0]:
            s_env += env[j] * t_cur
        if j < n_drive:
            s_drive += drive[j] * t_cur
    slope = (params[P_SPRING0] + params[P_SPRING_RATE] * t) * theta + s_env
    if n_drive > 0:
        slope += math.sin(drive_omega * (t - drive_t0)) * s_drive
    if mode != FREE:
        slope += mode * (params[P_K_STOP] * (mode * theta - params[P_STOP]) + params[P_C_STOP] * mode * omega)
    return -slope * params[P_INV_INERTIA] - params[P_TWO_DELTA] * omega


@njit(cache=True)
def contact_mode(theta, omega, params):
    """The mode in which (θ, θ') lies: in contact while penetrating and the stop pushes (never pulls)."""
    side = 1.0 if theta > 0.0 else -1.0
    penetration = side * theta - params[P_STOP]
    pushing = params[P_K_STOP] * penetration + params[P_C_STOP] * side * omega > 0.0
    return side if penetration > 0.0 and pushing else FREE


@njit(cache=True)
def _event(theta, omega, mode, params):
    """> 0 while ``mode`` holds: clearance to the stop when free, the stop's push in contact."""
    if mode == FREE:
        return params[P_STOP] - abs(theta)
    return params[P_K_STOP] * (mode * theta - params[P_STOP]) + params[P_C_STOP] * mode * omega


@njit(cache=True)
def _event_rate(theta, omega, t, mode, params, env, drive, drive_omega, drive_t0):
    """d/dt of :func:`_event` along the motion."""
    if mode == FREE:
        return -omega if theta > 0.0 else omega
    a = acceleration(theta, omega, t, mode, params, env, drive, drive_omega, drive_t0)
    return mode * (params[P_K_STOP] * omega + params[P_C_STOP] * a)


@njit(cache=True)
def _rk4_step(theta, omega, t, h, mode, params, env, drive, drive_omega, drive_t0):
    a1 = acceleration(theta, omega, t, mode, params, env, drive, drive_omega, drive_t0)
    o2 = omega + 0.5 * h * a1
    a2 = acceleration(theta + 0.5 * h * omega, o2, t + 0.5 * h, mode, params, env, drive, drive_omega, drive_t0)
    o3 = omega + 0.5 * h * a2
    a3 = acceleration(theta + 0.5 * h * o2, o3, t + 0.5 * h, mode, params, env, drive, drive_omega, drive_t0)
    o4 = omega + h * a3
    a4 = acceleration(theta + h * o3, o4, t + h, mode, params, env, drive, drive_omega, drive_t0)
    return (theta + h / 6.0 * (omega + 2.0 * o2 + 2.0 * o3 + o4),
            omega + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4))


@njit(cache=True)
def _step(theta, omega, mode, t, h, params, env, drive, drive_omega, drive_t0):
    """One RK4 step of length h that stops at every change of contact mode inside it.

    Within a mode the force is smooth, so RK4 keeps its order across impacts: the instant
    where :func:`_event` reaches zero is found by Newton's method on the step fraction, the
    step is taken up to it, the mode switches, and the rest of the step follows.
    """
    for _ in range(MAX_EVENTS_PER_STEP):
        theta1, omega1 = _rk4_step(theta, omega, t, h, mode, params, env, drive, drive_omega, drive_t0)
        g0 = _event(theta, omega, mode, params)
        g1 = _event(theta1, omega1, mode, params)
        if not (g0 >= 0.0 and g1 < 0.0):
            return theta1, omega1, mode
        fraction = g0 / (g0 - g1)
        for _ in range(EVENT_NEWTON_STEPS):
            theta1, omega1 = _rk4_step(theta, omega, t, fraction * h, mode, params, env, drive, drive_omega, drive_t0)
            rate = _event_rate(theta1, omega1, t + fraction * h, mode, params, env, drive, drive_omega, drive_t0)
            if rate == 0.0:
                break
            fraction = min(max(fraction - _event(theta1, omega1, mode, params) / (rate * h), 0.0), 1.0)
        theta, omega = _rk4_step(theta, omega, t, fraction * h, mode, params, env, drive, drive_omega, drive_t0)
        t += fraction * h
        h -= fraction * h
        mode = (1.0 if theta > 0.0 else -1.0) if mode == FREE else FREE
    return _rk4_step(theta, omega, t, h, mode, params, env, drive, drive_omega, drive_t0) + (mode,)


@njit(cache=True)
def advance(state, first_index, sample_rate_hz, substeps, contact_substeps, params, env, drive, drive_omega,
            drive_t0, theta_out, omega_out):
    """Record (θ, θ') at samples first_index … first_index + n − 1 and integrate to the next.

    ``state`` = [θ, θ', contact mode] is updated in place. Returns the number of samples done;
    fewer than n if θ left the Chebyshev interval (|x| > 1), where the series is no longer
    the potential.
    """
    theta, omega, mode = state[0], state[1], state[2]
    dt = 1.0 / sample_rate_hz
    for i in range(theta_out.shape[0]):
        if abs(theta) * params[P_INV_WIDTH] > 1.0:
            state[0], state[1], state[2] = theta, omega, mode
            return i
        theta_out[i] = theta
        omega_out[i] = omega
        t = (first_index + i) * dt
        near = mode != FREE or abs(theta) + 2.0 * abs(omega) * dt + CONTACT_MARGIN_RAD >= params[P_STOP]
        steps = contact_substeps if near else substeps
        h = dt / steps
        for k in range(steps):
            theta, omega, mode = _step(theta, omega, mode, t + k * h, h, params, env, drive, drive_omega, drive_t0)
    state[0], state[1], state[2] = theta, omega, mode
    return theta_out.shape[0]


# --- noise as a stream ---------------------------------------------------------------------
class NoiseStream:
    """:class:`mows.physics.fluxgate.NoiseModel` noise, continuous across blocks.

    Every sample consumes four standard normals in order (common white, 1/f driver, sensor 1,
    sensor 2), so the stream does not depend on how it is cut into blocks. The 1/f part is
    white noise through a fixed filter of real pole–zero pairs spaced
    :data:`PINK_POLES_PER_DECADE` per decade from :data:`PINK_LOW_HZ` to fs/2 (each zero half
    a spacing above its pole: on average −10 dB/decade, within 0.05 dB of 1/f from 0.1 Hz to
    1 kHz, flat below 0.01 Hz), mapped to the sampled domain by z = e^(−2πf/fs) and scaled to
    the model's ASD at 1 Hz. Its state is
    carried from block to block, so the 1/f noise has no discontinuity at block edges; it
    starts at rest, so its content below ~0.1 Hz builds up over the first ~10 s (a slow
    offset, which the ring-down fit absorbs anyway). Mains hum is a sine of device time.
    """

    def __init__(self, model, sample_rate_hz: float, rng: np.random.Generator):
        self.model = model
        self.sample_rate_hz = float(sample_rate_hz)
        self.rng = rng
        self._mains_phase = rng.uniform(0.0, TWO_PI)
        self._sos, self._pink_gain = pink_filter(self.sample_rate_hz, model.common_pink_t_per_rthz_at_1hz)
        self._state = np.zeros((self._sos.shape[0], 2))

    def draw(self, first_index: int, n: int) -> np.ndarray:
        """Noise of samples first_index … first_index + n − 1 of both channels, tesla, (n, 2)."""
        m = self.model
        silent = not (m.common_white_t_per_rthz or m.common_pink_t_per_rthz_at_1hz or m.sensor_white_t_per_rthz
                      or m.mains_t)
        if silent or n == 0:
            return np.zeros((n, 2))  # nothing to draw
        normals = self.rng.standard_normal((n, 4))
        white_scale = math.sqrt(self.sample_rate_hz / 2.0)  # per-sample σ of a one-sided ASD of 1
        pink, self._state = sp_signal.sosfilt(self._sos, normals[:, 1], zi=self._state)
        t = (first_index + np.arange(n)) / self.sample_rate_hz
        common = (m.common_white_t_per_rthz * white_scale * normals[:, 0] + self._pink_gain * pink
                  + m.mains_t * np.sin(TWO_PI * m.mains_hz * t + self._mains_phase))
        return common[:, None] + m.sensor_white_t_per_rthz * white_scale * normals[:, 2:]


def pink_filter(sample_rate_hz: float, asd_at_1hz_t_per_rthz: float):
    """(sos, gain): unit white noise through ``sos`` × gain has one-sided ASD asd·(f/1 Hz)^(−1/2)."""
    spacing = 10.0 ** (1.0 / PINK_POLES_PER_DECADE)
    n_pairs = int(math.ceil(math.log10(sample_rate_hz / 2.0 / PINK_LOW_HZ) * PINK_POLES_PER_DECADE))
    poles_hz = PINK_LOW_HZ * spacing ** np.arange(n_pairs)
    zeros_hz = poles_hz * math.sqrt(spacing)
    sos = sp_signal.zpk2sos(np.exp(-TWO_PI * zeros_hz / sample_rate_hz), np.exp(-TWO_PI * poles_hz / sample_rate_hz),
                            1.0)
    _, response = sp_signal.sosfreqz(sos, worN=[1.0], fs=sample_rate_hz)
    # Unit white noise has one-sided PSD 2/fs; the gain makes the output's PSD asd² at 1 Hz.
    return sos, asd_at_1hz_t_per_rthz * math.sqrt(sample_rate_hz / 2.0) / abs(response[0])


# --- what the device returns ---------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class SimulatedBlock:
    """What the device read (``samples``: a :class:`~mows.records.samples.SampleBlock` of both
    fluxgates, column 0 the near sensor, stamped on a device clock that starts at 0) and the
    simulation's truth at those samples, which hardware would not know: ``coils_on`` (n,),
    ``theta_rad`` and ``theta_dot_rad_per_s`` (n,), the coil currents ``currents_a``
    (n, n_coils)."""

    samples: SampleBlock
    coils_on: np.ndarray
    theta_rad: np.ndarray
    theta_dot_rad_per_s: np.ndarray
    currents_a: np.ndarray

    def __len__(self) -> int:
        return len(self.samples)

    @staticmethod
    def concatenate(blocks) -> SimulatedBlock:
        """One block of consecutive ``blocks``."""
        blocks = list(blocks)
        truth = {f.name: np.concatenate([getattr(b, f.name) for b in blocks])
                 for f in dataclasses.fields(SimulatedBlock) if f.name != "samples"}
        return SimulatedBlock(SampleBlock.concatenate(b.samples for b in blocks), **truth)


@dataclasses.dataclass(frozen=True, eq=False)
class DeviceTruth:
    """What the simulation knows and the hardware would not: the state and the potential."""

    time_s: float
    theta0_rad: float
    theta_rad: float
    theta_dot_rad_per_s: float
    rest_angle_rad: float
    temperature_k: float
    spring_nm_per_rad: float
    field_t: np.ndarray            # environment field at the magnet's rest position, global frame
    gradient_t_per_m: np.ndarray   # G[i, j] = ∂B_i/∂x_j there
    potential: ArcPotential        # U(θ) at this pose and temperature


class SimulatedDevice:
    """The MOWS device in a :class:`mows.sim.scenario.Scenario`, advanced sample by sample.

    The probe starts at rest at the scenario's orientation. ``rng`` defaults to
    ``numpy.random.default_rng(scenario.seed)``.
    """

    def __init__(self, scenario, rng: np.random.Generator | None = None):
        self.scenario = scenario
        self.probe = scenario.probe
        self.sample_rate_hz = float(scenario.sample_rate_hz)
        self.n_coils = len(scenario.setup.coils)
        self.sample_index = 0
        self._env_source = scenario.environment.source
        self._noise = NoiseStream(scenario.noise, self.sample_rate_hz,
                                  np.random.default_rng(scenario.seed) if rng is None else rng)
        pair = scenario.sensors.pair
        env_at_sensors = self._env_source.field_t(pair.positions_m)
        self._pair = pair.with_offsets_nulled(env_at_sensors) if scenario.sensors.null_offsets else pair
        self._env_reading_t = self._pair.component_t(env_at_sensors)                       # (2,)
        coil_fields = scenario.setup.coil_field_per_ampere_t(pair.positions_m)             # (2, K, 3)
        self._coil_reading_t_per_a = np.stack(
            [self._pair.component_t(coil_fields[:, k]) for k in range(self.n_coils)])       # (K, 2)
        self._half_width_rad = max(DEFAULT_HALF_WIDTH_RAD, INTERVAL_OVER_STOP * self.probe.theta_stop_rad)
        self._params = self._kernel_parameters()
        self._amplitudes_a = np.zeros(self.n_coils)
        self._drive_hz = 0.0
        self._drive_t0_s = 0.0
        self._coils_on = False
        self._state = np.zeros(3)  # θ, θ', contact mode
        self.set_orientation(scenario.pose.theta0_rad)
        rest = self.truth.rest_angle_rad
        self._state[0] = rest if math.isfinite(rest) else 0.0  # beyond spring cancellation: it buckles

    # --- set-up --------------------------------------------------------------------------
    def _kernel_parameters(self) -> np.ndarray:
        probe, env, housing = self.probe, self.scenario.environment, self.scenario.housing
        spring0 = probe.spring_at(env.temperature_k)
        spring_rate = probe.spring_nm_per_rad * probe.spring_temp_coeff_per_k * env.temperature_rate_k_per_s
        k_stop = housing.stiffness_ratio * probe.spring_nm_per_rad
        log_e = math.log(housing.restitution)
        zeta = -log_e / math.sqrt(math.pi**2 + log_e**2)
        c_stop = 2.0 * zeta * math.sqrt(k_stop * probe.inertia_kgm2)
        params = np.zeros(8)
        params[[P_INV_INERTIA, P_TWO_DELTA, P_SPRING0, P_SPRING_RATE, P_INV_WIDTH, P_STOP, P_K_STOP, P_C_STOP]] = (
            1.0 / probe.inertia_kgm2, 2.0 * probe.damping_per_s, spring0, spring_rate, 1.0 / self._half_width_rad,
            probe.theta_stop_rad, k_stop, c_stop)
        return params

    def _slope_series(self, source, pose) -> np.ndarray:
        """Chebyshev coefficients of W'(θ) for ``source`` at ``pose``, negligible tail dropped."""
        coeffs = ArcPotential.from_source(self.probe, source, pose, half_width_rad=self._half_width_rad).d1
        significant = np.flatnonzero(np.abs(coeffs) > SERIES_TOLERANCE * self.probe.spring_nm_per_rad
                                     * self._half_width_rad)
        return np.ascontiguousarray(coeffs[: max(2, significant[-1] + 1 if significant.size else 2)])

    @property
    def pose(self):
        return self._pose

    def set_orientation(self, theta0_rad: float) -> None:
        """The stage turns the probe to θ0 (instantly on the device clock; the deflection state
        is carried along). RuntimeError while the coils are on."""
        if self._coils_on:
            raise RuntimeError("set_orientation: switch the coils off before turning the probe")
        if not math.isfinite(theta0_rad):
            raise ValueError(f"theta0_rad = {theta0_rad!r} must be finite")
        self._pose = self.scenario.pose.with_theta0(theta0_rad)
        self._env_series = self._slope_series(self._env_source, self._pose)
        coil_pose = dataclasses.replace(self._pose, gravity_m_per_s2=(0.0, 0.0, 0.0))
        self._coil_series = [self._slope_series(coil, coil_pose) for coil in self.scenario.setup.coils]

    def set_coils(self, amplitudes_a, frequency_hz: float) -> None:
        """Drive coil k with amplitudes_a[k]·sin(2πf·(t − t_on)) from now (t_on = this sample).

        ValueError if a current exceeds the setup's cap, the count is not ``n_coils`` or the
        frequency is not in (0, fs/2).
        """
        amplitudes = self.scenario.setup.cap.check(amplitudes_a).reshape(-1)
        if amplitudes.shape != (self.n_coils,):
            raise ValueError(f"amplitudes_a has {amplitudes.size} values; the setup has {self.n_coils} coils")
        if not (math.isfinite(frequency_hz) and 0.0 < frequency_hz < self.sample_rate_hz / 2.0):
            raise ValueError(f"frequency_hz = {frequency_hz!r} must be in (0, {self.sample_rate_hz / 2.0:g}) Hz")
        self._amplitudes_a = amplitudes
        self._drive_hz = float(frequency_hz)
        self._drive_t0_s = self.sample_index / self.sample_rate_hz
        self._coils_on = True

    def coils_off(self) -> None:
        self._coils_on = False
        self._amplitudes_a = np.zeros(self.n_coils)

    def pluck(self, theta_rad: float, theta_dot_rad_per_s: float = 0.0) -> None:
        """Set the deflection state directly (simulation only: a plucked cantilever)."""
        if not abs(theta_rad) < self._half_width_rad or not math.isfinite(theta_dot_rad_per_s):
            raise ValueError(f"theta_rad = {theta_rad!r} must be within ±{self._half_width_rad:.3f} rad "
                             f"and theta_dot_rad_per_s = {theta_dot_rad_per_s!r} finite")
        self._state[:] = theta_rad, theta_dot_rad_per_s, contact_mode(theta_rad, theta_dot_rad_per_s, self._params)

    # --- running -------------------------------------------------------------------------
    def _drive_series(self, amplitudes_a) -> np.ndarray:
        """Chebyshev coefficients of Σ_k A_k·W_k'(θ); empty when every A_k is zero."""
        if not np.any(amplitudes_a):
            return np.zeros(0)
        total = np.zeros(max(len(s) for s in self._coil_series))
        for amplitude, series in zip(amplitudes_a, self._coil_series):
            total[: len(series)] += amplitude * series
        return total

    def equation_of_motion(self, amplitudes_a=None, frequency_hz: float = 0.0, drive_t0_s: float = 0.0):
        """rhs(t, [θ, θ']) → [θ', θ''] at the current pose, for other integrators (solve_ivp).

        Coil k carries amplitudes_a[k]·sin(2πf·(t − drive_t0_s)). The stop's contact mode is
        read from the state at each call, without the event location of the kernel.
        """
        drive = self._drive_series(np.zeros(self.n_coils) if amplitudes_a is None else amplitudes_a)
        params, env, drive_omega = self._params, self._env_series, TWO_PI * frequency_hz

        def rhs(t, y):
            mode = contact_mode(y[0], y[1], params)
            return [y[1], acceleration(y[0], y[1], t, mode, params, env, drive, drive_omega, drive_t0_s)]
        return rhs

    def integrate(self, n_samples: int):
        """Advance the probe by ``n_samples`` without reading the sensors: (θ, θ') at the samples."""
        if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 0):
            raise ValueError(f"n_samples = {n_samples!r} must be an integer ≥ 0")
        theta = np.empty(n_samples)
        theta_dot = np.empty(n_samples)
        integrator = self.scenario.integrator
        done = advance(self._state, self.sample_index, self.sample_rate_hz, integrator.substeps,
                       integrator.contact_substeps, self._params, self._env_series,
                       self._drive_series(self._amplitudes_a),
                       TWO_PI * self._drive_hz, self._drive_t0_s, theta, theta_dot)
        self.sample_index += done
        if done < n_samples:
            raise RuntimeError(f"the deflection θ = {self._state[0]:.3f} rad left the interval ±"
                               f"{self._half_width_rad:.3f} rad on which the potential is represented")
        return theta, theta_dot

    def idle(self, duration_s: float, chunk_samples: int = 20_000) -> None:
        """Let ``duration_s`` of device time pass unrecorded (the gap between repeats): the probe
        moves, the sensors are not read, so the noise stream resumes where it stopped."""
        remaining = int(round(duration_s * self.sample_rate_hz))
        while remaining > 0:
            remaining -= len(self.integrate(min(remaining, chunk_samples))[0])

    def currents_at(self, sample_indices) -> np.ndarray:
        """Coil currents at ``sample_indices`` under the present drive, A, shape (n, n_coils)."""
        t = np.asarray(sample_indices) / self.sample_rate_hz
        return np.sin(TWO_PI * self._drive_hz * (t - self._drive_t0_s))[:, None] * self._amplitudes_a

    def read(self, n_samples: int) -> SimulatedBlock:
        """The next ``n_samples`` samples of both fluxgates; the probe keeps moving afterwards."""
        first = self.sample_index
        currents = self.currents_at(first + np.arange(n_samples))
        theta, theta_dot = self.integrate(n_samples)
        positions = self._pose.magnet_position_at(theta, self.probe.lever_m)
        moments = self.probe.moment_am2 * self._pose.moment_direction_at(theta)
        field = (self._pair.pickup_t(positions, moments) + self._env_reading_t
                 + currents @ self._coil_reading_t_per_a + self._noise.draw(first, n_samples))
        readings, saturated = self._pair.digitise(field)
        samples = SampleBlock(first, round(first * NS_PER_S / self.sample_rate_hz), self.sample_rate_hz,
                              readings, saturated)
        return SimulatedBlock(samples, np.full(n_samples, self._coils_on), theta, theta_dot, currents)

    # --- truth ---------------------------------------------------------------------------
    @property
    def temperature_k(self) -> float:
        return float(self.scenario.environment.temperature_at(self.sample_index / self.sample_rate_hz))

    def potential(self) -> ArcPotential:
        """U(θ) of the probe in the environment at the current pose and temperature."""
        return ArcPotential.from_source(self.probe, self._env_source, self._pose, self.temperature_k,
                                        half_width_rad=self._half_width_rad)

    def expected_frequency_hz(self, amplitude_rad=0.0):
        """Ring-down frequency from the full potential at amplitude A (harmonic balance, Eq. S1)."""
        return float(self.potential().frequency_hz(amplitude_rad))

    @property
    def truth(self) -> DeviceTruth:
        potential = self.potential()
        where = np.asarray(self._pose.magnet_position_m, float)
        return DeviceTruth(
            time_s=self.sample_index / self.sample_rate_hz, theta0_rad=self._pose.theta0_rad,
            theta_rad=float(self._state[0]), theta_dot_rad_per_s=float(self._state[1]),
            rest_angle_rad=float(potential.rest_angle_rad()), temperature_k=self.temperature_k,
            spring_nm_per_rad=float(self.probe.spring_at(self.temperature_k)),
            field_t=self._env_source.field_t(where), gradient_t_per_m=self._env_source.gradient_t_per_m(where),
            potential=potential)


# --- one measurement cycle -----------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class CycleRecord:
    """One excitation and its ring-down. ``block`` holds the samples (and the truth θ(t));
    the ring-down starts at ``coil_off_index``; ``potential`` is U(θ) at the switch-off."""

    theta0_rad: float
    currents_a: np.ndarray
    frequency_hz: float
    block: SimulatedBlock
    coil_off_index: int
    potential: ArcPotential

    @property
    def sample_rate_hz(self) -> float:
        return self.block.samples.sample_rate_hz

    @property
    def samples_t(self) -> np.ndarray:
        return self.block.samples.samples_t

    @property
    def saturated(self) -> np.ndarray:
        return self.block.samples.saturated

    @property
    def theta_rad(self) -> np.ndarray:
        return self.block.theta_rad

    def expected_frequency_hz(self, amplitude_rad=0.0):
        """Truth f(A) from the full potential (harmonic balance, Eq. S1)."""
        return self.potential.frequency_hz(amplitude_rad)

    def ringdown_amplitude_rad(self) -> float:
        """The first swing after switch-off: max |θ − θs| over the first period of the ring-down."""
        period = int(math.ceil(self.sample_rate_hz / self.frequency_hz))
        theta = self.theta_rad[self.coil_off_index:self.coil_off_index + period]
        return float(np.max(np.abs(theta - self.potential.rest_angle_rad())))

    def ringdown_frequency_hz(self, duration_s: float, points: int = 32) -> float:
        """Truth for a fit of the first ``duration_s`` of the ring-down: the time average of
        f(A(t)) with A(t) = A0·e^(−δt) from the first swing A0 (the frequency drifts as the
        amplitude decays, PHYSICS.md §5.4)."""
        t = (np.arange(points) + 0.5) / points * duration_s
        amplitudes = self.ringdown_amplitude_rad() * np.exp(-float(self.potential.damping_per_s) * t)
        return float(np.mean([self.potential.frequency_hz(a) for a in amplitudes]))


def simulate_cycle(device: SimulatedDevice, theta0_rad: float, amplitude_a: float, frequency_hz=None,
                   excite_s: float = 0.5, ringdown_s: float = 0.5) -> CycleRecord:
    """Turn to θ0, drive the coils with the setup's current scheme for ``excite_s`` (base
    amplitude ``amplitude_a``; ``frequency_hz`` None: the expected small-amplitude frequency,
    as after the paper's tuning), switch them off and record ``ringdown_s`` of ring-down."""
    device.set_orientation(theta0_rad)
    frequency = device.expected_frequency_hz() if frequency_hz is None else float(frequency_hz)
    currents = device.scenario.setup.currents_a(theta0_rad, amplitude_a)
    device.set_coils(currents, frequency)
    excitation = device.read(int(round(excite_s * device.sample_rate_hz)))
    device.coils_off()
    potential = device.potential()
    ringdown = device.read(int(round(ringdown_s * device.sample_rate_hz)))
    return CycleRecord(float(theta0_rad), currents, frequency, SimulatedBlock.concatenate([excitation, ringdown]),
                       len(excitation), potential)
