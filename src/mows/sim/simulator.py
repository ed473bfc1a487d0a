"""The simulated MOWS device (:class:`SimulatedDevice`), sample by sample like the hardware (docs/physics.md §2, §4).

It integrates the probe's motion with the kernels of :mod:`mows.sim.kernel` (equation of
motion, housing stop, integrator and its step error are described there) and reads the two
fluxgates with the noise of :mod:`mows.sim.noise`; :mod:`mows.sim.cycle` runs one measurement
cycle on it.

Fluxgates. At every sample: the exact dipole field of the magnet at its actual position with
its actual moment (:meth:`mows.physics.fluxgate.FluxgatePair.pickup_t`; the moment at the
temperature of the cycle's phase, :meth:`mows.physics.probe.Probe.at_temperature`), plus the environment field,
plus each coil's field × its current (they saturate the sensors during excitation, as in the
paper), noise (:class:`mows.sim.noise.NoiseStream`), then offset compensation, ±range clipping and
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

from mows.physics.field import SumSource
from mows.physics.potential import DEFAULT_HALF_WIDTH_RAD, ArcPotential
from mows.records.samples import SampleBlock
from mows.records.stamps import NS_PER_S
from mows.sim.kernel import (
    P_C_STOP,
    P_INV_INERTIA,
    P_INV_WIDTH,
    P_K_STOP,
    P_SPRING0,
    P_SPRING_RATE,
    P_STOP,
    P_TWO_DELTA,
    TWO_PI,
    acceleration,
    advance,
    contact_mode,
)
from mows.sim.noise import NoiseStream

# The Chebyshev interval covers the stop with room for the contact's penetration.
INTERVAL_OVER_STOP = 1.5
# Chebyshev terms below this fraction of kM·w (N·m) are dropped from the kernel's series.
SERIES_TOLERANCE = 1e-15
# RK4 is stable for ω·dt below 2.78 on an undamped oscillator; half of that keeps it accurate.
RK4_MAX_OMEGA_DT = 1.4


class SimulationRefused(ValueError):
    """A scenario the simulator cannot integrate (a field so strong the lever rings faster than
    the integrator's steps resolve): a bad input, said before the first step."""


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
        truth = {
            f.name: np.concatenate([getattr(b, f.name) for b in blocks])
            for f in dataclasses.fields(SimulatedBlock)
            if f.name != "samples"
        }
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
    field_t: np.ndarray  # environment field at the magnet's rest position, global frame
    gradient_t_per_m: np.ndarray  # G[i, j] = ∂B_i/∂x_j there
    potential: ArcPotential  # U(θ) at this pose and temperature


class SimulatedDevice:
    """The MOWS device in a :class:`mows.sim.scenario.Scenario`, advanced sample by sample.

    The probe starts at rest at the scenario's orientation. ``rng`` defaults to
    ``numpy.random.default_rng(scenario.seed)``. A scene with several probes is refused
    (:class:`SimulationRefused`): simulating its first probe alone would leave out the others'
    ring-downs and their coupling (:class:`mows.sim.multiprobe_device.MultiProbeDevice` integrates them).
    """

    def __init__(self, scenario, rng: np.random.Generator | None = None):
        if len(scenario.probes) > 1:
            raise SimulationRefused(
                f"scenario {scenario.name!r} has {len(scenario.probes)} probes; this simulator integrates one "
                "(MultiProbeDevice integrates several, as the driver's sim backend does)"
            )
        self.scenario = scenario
        self.probe = scenario.probe
        self.sample_rate_hz = float(scenario.sample_rate_hz)
        self.n_coils = len(scenario.setup.coils)
        self.sample_index = 0
        self._fixed_source = scenario.environment.source
        self._supply = scenario.supply
        self.field_current_a = 0.0 if self._supply is None else self._supply.current_a
        self._noise = NoiseStream(
            scenario.noise, self.sample_rate_hz, np.random.default_rng(scenario.seed) if rng is None else rng
        )
        pair = scenario.sensors.pair
        env_at_sensors = self.static_source.field_t(pair.positions_m)
        self._pair = pair.with_offsets_nulled(env_at_sensors) if scenario.sensors.null_offsets else pair
        self._fixed_reading_t = self._pair.component_t(self._fixed_source.field_t(pair.positions_m))  # (2,)
        self._supply_reading_t_per_a = (
            np.zeros(2)
            if self._supply is None
            else self._pair.component_t(self._supply.source.field_t(pair.positions_m))
        )
        coil_fields = scenario.setup.coil_field_per_ampere_t(pair.positions_m)  # (2, K, 3)
        self._coil_reading_t_per_a = np.stack(
            [self._pair.component_t(coil_fields[:, k]) for k in range(self.n_coils)]
        )  # (K, 2)
        self._half_width_rad = max(DEFAULT_HALF_WIDTH_RAD, INTERVAL_OVER_STOP * self.probe.theta_stop_rad)
        self._check_resolvable()
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
    def _check_resolvable(self) -> None:
        """Refuse a field whose spring m·|B| makes ω = √((kM + m|B|)/J) too fast for the
        integrator's step 1/(substeps·fs) (Eq. S1 with the field's spring added)."""
        probe, integrator = self.probe, self.scenario.integrator
        field_t = float(
            np.linalg.norm(self.static_source.field_t(np.asarray(self.scenario.pose.magnet_position_m, float)))
        )
        omega = math.sqrt((probe.spring_nm_per_rad + probe.moment_am2 * field_t) / probe.inertia_kgm2)
        omega_dt = omega / (integrator.substeps * self.sample_rate_hz)
        if not omega_dt < RK4_MAX_OMEGA_DT:
            needed = math.ceil(omega / (RK4_MAX_OMEGA_DT * self.sample_rate_hz))
            raise SimulationRefused(
                f"the field at the probe, |B| = {field_t:.4g} T, makes the lever ring at {omega / TWO_PI:.4g} Hz, "
                f"faster than integrator substeps = {integrator.substeps} at {self.sample_rate_hz:g} S/s resolve "
                f"(ω·dt = {omega_dt:.3g}, must stay below {RK4_MAX_OMEGA_DT}): use a weaker field or "
                f"integrator: substeps ≥ {needed}"
            )

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
            1.0 / probe.inertia_kgm2,
            2.0 * probe.damping_per_s,
            spring0,
            spring_rate,
            1.0 / self._half_width_rad,
            probe.theta_stop_rad,
            k_stop,
            c_stop,
        )
        return params

    def _slope_series(self, source, pose) -> np.ndarray:
        """Chebyshev coefficients of W'(θ) for ``source`` at ``pose``, negligible tail dropped."""
        coeffs = ArcPotential.from_source(self._magnet, source, pose, half_width_rad=self._half_width_rad).d1
        significant = np.flatnonzero(
            np.abs(coeffs) > SERIES_TOLERANCE * self.probe.spring_nm_per_rad * self._half_width_rad
        )
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
        self._magnet = self._magnet_now()
        self._build_series()

    def _build_series(self) -> None:
        """W' of every source at the present pose, for the magnet's present moment."""
        self._fixed_series = self._slope_series(self._fixed_source, self._pose)
        coil_pose = dataclasses.replace(self._pose, gravity_m_per_s2=(0.0, 0.0, 0.0))
        self._coil_series = [self._slope_series(coil, coil_pose) for coil in self.scenario.setup.coils]
        self._supply_series = (
            np.zeros(0) if self._supply is None else self._slope_series(self._supply.source, coil_pose)
        )
        self._combine_static()

    def set_field_current(self, current_a: float) -> None:
        """The supply drives its source at ``current_a`` from this sample on (a step: the
        slew limit is the caller's staircase, :meth:`mows.physics.supply.SupplyLimits.ramp`).
        ValueError above the supply's cap or without a supply in the scenario."""
        if self._supply is None:
            raise ValueError("set_field_current: the scenario has no field supply (section 'supply')")
        self.field_current_a = self._supply.limits.check(current_a)
        self._combine_static()

    @property
    def static_source(self):
        """The static field: the environment plus the supply's source at its present current."""
        if self._supply is None or self.field_current_a == 0.0:
            return self._fixed_source
        return SumSource((self._fixed_source, self._supply.source.scaled(self.field_current_a)))

    def _combine_static(self) -> None:
        """W' of the static field and its reading at the sensors: both are linear in the
        supply current, so a new current costs one sum, not a new series."""
        n = max(len(self._fixed_series), len(self._supply_series))
        series = np.zeros(n)
        series[: len(self._fixed_series)] += self._fixed_series
        series[: len(self._supply_series)] += self.field_current_a * self._supply_series
        self._env_series = series
        self._env_reading_t = self._fixed_reading_t + self.field_current_a * self._supply_reading_t_per_a

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
        self._hold_moment()
        self._amplitudes_a = amplitudes
        self._drive_hz = float(frequency_hz)
        self._drive_t0_s = self.sample_index / self.sample_rate_hz
        self._coils_on = True

    def _magnet_now(self):
        """The probe with its magnet's moment at the present temperature, m(T) (Probe.at_temperature)."""
        return self.probe.at_temperature(self.temperature_k)

    def _hold_moment(self) -> None:
        """Take the moment at the present temperature and hold it until the cycle's next phase
        (the probe turned, the coils on, the coils off), in the potential, the coils' torque
        and the fluxgates' pickup. A phase lasts ~0.5 s: the temperature moves by its rate ×
        0.5 s, a few mK in a warming lab, a relative change of the moment ~1e-6, below what
        one ring-down resolves; taken at the switch-off, the ring-down sees the moment of its
        own start. The spring, whose drift the kernel follows continuously, is not scaled."""
        magnet = self._magnet_now()
        if magnet != self._magnet:
            self._magnet = magnet
            self._build_series()

    def coils_off(self) -> None:
        self._hold_moment()
        self._coils_on = False
        self._amplitudes_a = np.zeros(self.n_coils)

    def pluck(self, theta_rad: float, theta_dot_rad_per_s: float = 0.0) -> None:
        """Set the deflection state directly (simulation only: a plucked cantilever)."""
        if not abs(theta_rad) < self._half_width_rad or not math.isfinite(theta_dot_rad_per_s):
            raise ValueError(
                f"theta_rad = {theta_rad!r} must be within ±{self._half_width_rad:.3f} rad "
                f"and theta_dot_rad_per_s = {theta_dot_rad_per_s!r} finite"
            )
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
        done = advance(
            self._state,
            self.sample_index,
            self.sample_rate_hz,
            integrator.substeps,
            integrator.contact_substeps,
            self._params,
            self._env_series,
            self._drive_series(self._amplitudes_a),
            TWO_PI * self._drive_hz,
            self._drive_t0_s,
            theta,
            theta_dot,
        )
        self.sample_index += done
        if done < n_samples:
            raise RuntimeError(
                f"the deflection θ = {self._state[0]:.4g} rad left the interval ±"
                f"{self._half_width_rad:.3f} rad on which the potential is represented"
            )
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
        moments = self._magnet.moment_am2 * self._pose.moment_direction_at(theta)
        field = (
            self._pair.pickup_t(positions, moments)
            + self._env_reading_t
            + currents @ self._coil_reading_t_per_a
            + self._noise.draw(first, n_samples)
        )
        readings, saturated = self._pair.digitise(field)
        samples = SampleBlock(
            first, round(first * NS_PER_S / self.sample_rate_hz), self.sample_rate_hz, readings, saturated
        )
        return SimulatedBlock(samples, np.full(n_samples, self._coils_on), theta, theta_dot, currents)

    # --- truth ---------------------------------------------------------------------------
    @property
    def temperature_k(self) -> float:
        return float(self.scenario.environment.temperature_at(self.sample_index / self.sample_rate_hz))

    def potential(self) -> ArcPotential:
        """U(θ) of the probe in the environment at the current pose and temperature."""
        return ArcPotential.from_source(
            self._magnet, self.static_source, self._pose, self.temperature_k, half_width_rad=self._half_width_rad
        )

    def expected_frequency_hz(self, amplitude_rad=0.0):
        """Ring-down frequency from the full potential at amplitude A (harmonic balance, Eq. S1)."""
        return float(self.potential().frequency_hz(amplitude_rad))

    @property
    def truth(self) -> DeviceTruth:
        potential = self.potential()
        where = np.asarray(self._pose.magnet_position_m, float)
        return DeviceTruth(
            time_s=self.sample_index / self.sample_rate_hz,
            theta0_rad=self._pose.theta0_rad,
            theta_rad=float(self._state[0]),
            theta_dot_rad_per_s=float(self._state[1]),
            rest_angle_rad=float(potential.rest_angle_rad()),
            temperature_k=self.temperature_k,
            spring_nm_per_rad=float(self.probe.spring_at(self.temperature_k)),
            field_t=self.static_source.field_t(where),
            gradient_t_per_m=self.static_source.gradient_t_per_m(where),
            potential=potential,
        )
