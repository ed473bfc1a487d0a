"""The simulated MOWS device (:class:`SimulatedDevice`) with every probe of its scene, sample by
sample like the hardware (docs/physics.md §2, §4; docs/multi_probe.md). One probe is a scene of one.

It integrates the probes' motion together with the kernels of :mod:`mows.sim.kernel` (equation
of motion, the neighbours' coupling, housing stop, integrator and its step error are described
there) and reads the two fluxgates with the noise of :mod:`mows.sim.noise`; the driver's measurement
cycle runs on it in device time (:mod:`mows.device.stream.simulated_cycle`).

Drive. The coils carry one sinusoid per coil (:meth:`SimulatedDevice.set_coils`, the current
scheme of one probe) or the sum of the tones of several probes
(:meth:`SimulatedDevice.drive`, :func:`mows.physics.multitone.drive_currents_a`), from the sample
they switch on to the sample they switch off.

Fluxgates. At every sample: the exact dipole field of every magnet at its actual position with
its actual moment (:func:`swinging_pickup_t`; the moment at the temperature of the cycle's phase,
:meth:`mows.physics.probe.Probe.at_temperature`), plus the environment field, plus each coil's
field × its current (they saturate the sensors during excitation, as in the paper), noise
(:class:`mows.sim.noise.NoiseStream`), then offset compensation, ±range clipping and
quantisation (:meth:`mows.physics.fluxgate.FluxgatePair.digitise`). A magnet is a point dipole:
a 1 mm cylinder's next multipole is ~(0.5 mm/6 cm)² ≈ 1e-4 of its field at the sensors.

Stages. :meth:`SimulatedDevice.set_orientations` turns each probe to its θ0 between excitations
(instantly on the device clock, the deflections carried along); a scene's probes on the shared
stage are turned by the caller with one angle added to their home orientations.

Device clock. Sample i is taken at t = i/fs; :meth:`SimulatedDevice.read` returns the next n
samples and leaves the probes moving, so consecutive reads form one continuous stream
(noise included) and a read of 2n equals two reads of n.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from mows.physics.coupling import PlacedProbe, coupled_rest, external_source
from mows.physics.field import SumSource
from mows.physics.fluxgate import FluxgatePair
from mows.physics.multitone import Tone, coil_amplitudes_a, peak_current_a
from mows.physics.potential import DEFAULT_HALF_WIDTH_RAD, ArcPotential
from mows.records.samples import SampleBlock
from mows.records.stamps import NS_PER_S
from mows.sim.kernel import (
    G_LEVER,
    G_MOMENT,
    G_PIVOT,
    G_X_AXIS,
    G_Y_AXIS,
    HEAD,
    P_C_STOP,
    P_INV_INERTIA,
    P_INV_WIDTH,
    P_K_STOP,
    P_SPRING0,
    P_SPRING_RATE,
    P_STOP,
    P_TWO_DELTA,
    accelerations,
    advance,
    contact_mode,
    coupling_torques,
    kernel_table,
)
from mows.sim.noise import NoiseStream

# The Chebyshev interval covers the stop with room for the contact's penetration.
INTERVAL_OVER_STOP = 1.5
# Chebyshev terms below this fraction of kM·w (N·m) are dropped from the kernel's series.
SERIES_TOLERANCE = 1e-15
# RK4 is stable for ω·dt below 2.78 on an undamped oscillator; half of that keeps it accurate.
RK4_MAX_OMEGA_DT = 1.4
# The off sample of a drive that runs until it is switched off.
NEVER = 2**62


class SimulationRefused(ValueError):
    """A scenario the simulator cannot integrate (a field so strong the lever rings faster than
    the integrator's steps resolve): a bad input, said before the first step."""


def swinging_pickup_t(pair: FluxgatePair, placed: Sequence[PlacedProbe], theta_rad: np.ndarray) -> np.ndarray:
    """What both fluxgates of ``pair`` read, (n, 2) T, of the magnets ``placed`` swinging through
    the deflections ``theta_rad`` (n, N): each magnet's exact dipole field (Eq. S8) on its
    lever, summed."""
    field = np.zeros((theta_rad.shape[0], 2))
    for k, p in enumerate(placed):
        positions = p.pose.magnet_position_at(theta_rad[:, k], p.probe.lever_m)
        field += pair.pickup_t(positions, p.probe.moment_am2 * p.pose.moment_direction_at(theta_rad[:, k]))
    return field


# --- what the device returns ---------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class SimulatedBlock:
    """What the device read (``samples``: a :class:`~mows.records.samples.SampleBlock` of both
    fluxgates, column 0 the near sensor, stamped on a device clock that starts at 0) and the
    simulation's truth at those samples, which hardware would not know: ``coils_on`` (n,), each
    probe's ``theta_rad`` and ``theta_dot_rad_per_s`` (n, N), the coil currents ``currents_a``
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
    """What the simulation knows and the hardware would not: each probe's state (N,) and potential."""

    time_s: float
    theta0_rad: np.ndarray
    theta_rad: np.ndarray
    theta_dot_rad_per_s: np.ndarray
    rest_angle_rad: np.ndarray
    temperature_k: float
    spring_nm_per_rad: np.ndarray
    field_t: np.ndarray  # (N, 3) static field at each magnet's rest position, global frame, neighbours left out
    gradient_t_per_m: np.ndarray  # (N, 3, 3) G[i, j] = ∂B_i/∂x_j there
    potentials: tuple[ArcPotential, ...]  # U(θ) of each probe at this pose and temperature


class SimulatedDevice:
    """The MOWS device in a :class:`mows.sim.scenario.Scenario` with all of its probes
    (:meth:`mows.sim.scenario.Scenario.placed_probes`), advanced sample by sample.

    The probes start at rest, in each other's fields, at the orientations ``theta0_rad`` (N,)
    (default: their home orientations). ``rng`` defaults to
    ``numpy.random.default_rng(scenario.seed)``. ``probe`` is the scenario's (its first probe's,
    with several).
    """

    def __init__(self, scenario, rng: np.random.Generator | None = None, theta0_rad: ArrayLike | None = None):
        self.scenario = scenario
        self.probe = scenario.probe
        self.setup = scenario.setup
        self.placed = tuple(scenario.placed_probes())
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
        stop_rad = max(p.probe.theta_stop_rad for p in self.placed)
        self.half_width_rad = max(DEFAULT_HALF_WIDTH_RAD, INTERVAL_OVER_STOP * stop_rad)
        self._check_resolvable()
        self._head = self._kernel_parameters()
        self._tone_amplitudes_a = np.zeros((0, self.n_coils))  # (tones, coils)
        self._tone_omegas = np.zeros(0)
        self._drive_series, self._drive_omegas = np.zeros((0, len(self.placed), 0)), np.zeros(0)
        self._drive_on_index = self._drive_off_index = 0
        self._state = np.zeros((3, len(self.placed)))  # θ, θ', contact mode of each probe
        self._magnets = self._magnets_now()
        self.set_orientations([p.pose.theta0_rad for p in self.placed] if theta0_rad is None else theta0_rad)
        rest = self.truth.rest_angle_rad
        self._state[0] = np.where(np.isfinite(rest), rest, 0.0)  # beyond spring cancellation: it buckles

    # --- set-up --------------------------------------------------------------------------
    def _check_resolvable(self) -> None:
        """Refuse a field whose spring m·|B| makes ω = √((kM + m|B|)/J) too fast for the
        integrator's step 1/(substeps·fs) (Eq. S1 with the field's spring added), for any probe."""
        substeps = self.scenario.integrator.substeps
        for p in self.placed:
            probe = p.probe
            field_t = float(np.linalg.norm(self.static_source.field_t(np.asarray(p.pose.magnet_position_m, float))))
            omega = math.sqrt((probe.spring_nm_per_rad + probe.moment_am2 * field_t) / probe.inertia_kgm2)
            omega_dt = omega / (substeps * self.sample_rate_hz)
            if not omega_dt < RK4_MAX_OMEGA_DT:
                needed = math.ceil(omega / (RK4_MAX_OMEGA_DT * self.sample_rate_hz))
                raise SimulationRefused(
                    f"the field at the probe, |B| = {field_t:.4g} T, makes the lever ring at "
                    f"{omega / math.tau:.4g} Hz, "
                    f"faster than integrator substeps = {substeps} at {self.sample_rate_hz:g} S/s resolve "
                    f"(ω·dt = {omega_dt:.3g}, must stay below {RK4_MAX_OMEGA_DT}): use a weaker field or "
                    f"integrator: substeps ≥ {needed}"
                )

    def _kernel_parameters(self) -> np.ndarray:
        """(N, HEAD): each probe's head of the kernel's table, its parameters (the P_* columns;
        the geometry, G_*, follows its orientation: :meth:`_build_series`)."""
        env, housing = self.scenario.environment, self.scenario.housing
        params = np.zeros((len(self.placed), HEAD))
        for row, p in zip(params, self.placed):
            probe = p.probe
            spring_rate = probe.spring_nm_per_rad * probe.spring_temp_coeff_per_k * env.temperature_rate_k_per_s
            k_stop = housing.stiffness_ratio * probe.spring_nm_per_rad
            log_e = math.log(housing.restitution)
            zeta = -log_e / math.sqrt(math.pi**2 + log_e**2)
            row[[P_INV_INERTIA, P_TWO_DELTA, P_SPRING0, P_SPRING_RATE, P_INV_WIDTH, P_STOP, P_K_STOP, P_C_STOP]] = (
                1.0 / probe.inertia_kgm2,
                2.0 * probe.damping_per_s,
                probe.spring_at(env.temperature_k),
                spring_rate,
                1.0 / self.half_width_rad,
                probe.theta_stop_rad,
                k_stop,
                2.0 * zeta * math.sqrt(k_stop * probe.inertia_kgm2),
            )
        return params

    def _slope_series(self, magnet, source, pose) -> np.ndarray:
        """Chebyshev coefficients of W'(θ) of ``magnet`` in ``source`` at ``pose``, negligible tail dropped."""
        coeffs = ArcPotential.from_source(magnet, source, pose, half_width_rad=self.half_width_rad).d1
        significant = np.flatnonzero(np.abs(coeffs) > SERIES_TOLERANCE * magnet.spring_nm_per_rad * self.half_width_rad)
        return np.ascontiguousarray(coeffs[: max(2, significant[-1] + 1 if significant.size else 2)])

    @property
    def theta0_rad(self) -> np.ndarray:
        """(N,): each probe's present orientation."""
        return np.array([p.pose.theta0_rad for p in self.placed])

    @property
    def pose(self):
        """The first probe's pose (the only one's, in a scene of one)."""
        return self.placed[0].pose

    def set_orientations(self, theta0_rad: ArrayLike) -> None:
        """Each probe's stage turns it to its θ0 (N,) (instantly on the device clock; the
        deflection states are carried along). RuntimeError while the coils are on."""
        if self.coils_on:
            raise RuntimeError("set_orientations: switch the coils off before turning the probes")
        angles = np.asarray(theta0_rad, float)
        if angles.shape != (len(self.placed),) or not np.all(np.isfinite(angles)):
            raise ValueError(f"theta0_rad = {theta0_rad!r} must give one finite angle per probe ({len(self.placed)})")
        self.placed = tuple(self.scenario.placed_probes(angles))
        self._magnets = self._magnets_now()
        self._build_series()

    def _build_series(self) -> None:
        """W' of every source for every probe at its present pose, for its magnet's present
        moment, and the probes' geometry for their coupling."""
        poses = [p.pose for p in self.placed]
        no_gravity = [dataclasses.replace(pose, gravity_m_per_s2=(0.0, 0.0, 0.0)) for pose in poses]
        self._fixed_series = [self._slope_series(m, self._fixed_source, pose) for m, pose in zip(self._magnets, poses)]
        self._coil_series = [
            [self._slope_series(m, coil, pose) for m, pose in zip(self._magnets, no_gravity)]
            for coil in self.setup.coils
        ]  # [coil][probe]
        self._supply_series = [
            np.zeros(0) if self._supply is None else self._slope_series(m, self._supply.source, pose)
            for m, pose in zip(self._magnets, no_gravity)
        ]
        for row, m, pose in zip(self._head, self._magnets, poses):
            x_axis, y_axis, _ = pose.axes()
            row[G_MOMENT], row[G_LEVER] = m.moment_am2, m.lever_m
            row[G_PIVOT : G_PIVOT + 3] = pose.pivot_m(m.lever_m)
            row[G_X_AXIS : G_X_AXIS + 3], row[G_Y_AXIS : G_Y_AXIS + 3] = x_axis, y_axis
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
        """W' of the static field for every probe (N, n) and its reading at the sensors: both
        are linear in the supply current, so a new current costs one sum, not a new series."""
        n = max(max(len(f), len(s)) for f, s in zip(self._fixed_series, self._supply_series))
        series = np.zeros((len(self.placed), n))
        for row, fixed, supply in zip(series, self._fixed_series, self._supply_series):
            row[: len(fixed)] += fixed
            row[: len(supply)] += self.field_current_a * supply
        self._env_series = series
        self._env_reading_t = self._fixed_reading_t + self.field_current_a * self._supply_reading_t_per_a
        self._pack()

    def _pack(self) -> None:
        """The kernel's table of the present parameters, geometry, static field and drive."""
        self._table = kernel_table(self._head, self._env_series, self._drive_series, self._drive_omegas)

    def set_coils(self, amplitudes_a, frequency_hz: float) -> None:
        """Drive coil k with amplitudes_a[k]·sin(2πf·(t − t_on)) from now (t_on = this sample)
        until :meth:`coils_off`.

        ValueError if a current exceeds the setup's cap, the count is not ``n_coils`` or the
        frequency is not in (0, fs/2).
        """
        amplitudes = self.setup.cap.check(amplitudes_a).reshape(-1)
        if amplitudes.shape != (self.n_coils,):
            raise ValueError(f"amplitudes_a has {amplitudes.size} values; the setup has {self.n_coils} coils")
        if not (math.isfinite(frequency_hz) and 0.0 < frequency_hz < self.sample_rate_hz / 2.0):
            raise ValueError(f"frequency_hz = {frequency_hz!r} must be in (0, {self.sample_rate_hz / 2.0:g}) Hz")
        self._switch_on(amplitudes[None, :], np.array([float(frequency_hz)]), NEVER)

    def drive(self, tones: Sequence[Tone], off_index: int) -> None:
        """The coils carry the sum of ``tones`` from this sample until sample ``off_index``
        (exclusive). ValueError if the summed peak over that span is above the setup's cap."""
        off = int(off_index)
        if off <= self.sample_index or not tones:
            raise ValueError(f"drive: tones {tones!r} until sample {off_index!r} must be some tones over a later span")
        duration_s = (off - self.sample_index) / self.sample_rate_hz
        peak = float(peak_current_a(self.setup, tones, duration_s).max())
        if peak > self.setup.cap.limit_a:
            raise ValueError(f"drive: the tones peak at {peak:.6g} A, above the {self.setup.cap.limit_a:g} A cap")
        self._switch_on(coil_amplitudes_a(self.setup, tones), np.array([t.frequency_hz for t in tones]), off)

    def _switch_on(self, amplitudes_a: np.ndarray, frequencies_hz: np.ndarray, off_index: int) -> None:
        """Tones of coil amplitudes (K, n_coils) at ``frequencies_hz`` (K,) from this sample to ``off_index``."""
        self._hold_moment()
        self._tone_amplitudes_a = amplitudes_a
        self._tone_omegas = math.tau * frequencies_hz
        self._drive_on_index, self._drive_off_index = self.sample_index, off_index
        self._drive_series, self._drive_omegas = self._drive_of(self._tone_amplitudes_a, self._tone_omegas)
        self._pack()

    def _drive_of(self, amplitudes_a: np.ndarray, omegas: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Chebyshev coefficients (K, N, n) of Σ_c A_kc·W_ic'(θ) of every tone k of coil amplitudes
        ``amplitudes_a`` (K, n_coils) not all zero, for every probe i, and those tones' ``omegas``."""
        active = np.flatnonzero(np.any(amplitudes_a != 0.0, axis=1))
        n = max(len(s) for coil in self._coil_series for s in coil) if active.size else 0
        series = np.zeros((active.size, len(self.placed), n))
        for row, tone in zip(series, active):
            for amplitude, coil in zip(amplitudes_a[tone], self._coil_series):
                for probe_row, s in zip(row, coil):
                    probe_row[: len(s)] += amplitude * s
        return series, omegas[active]

    @property
    def coils_on(self) -> bool:
        return self._drive_on_index <= self.sample_index < self._drive_off_index

    def _magnets_now(self) -> tuple:
        """Each probe with its magnet's moment at the present temperature, m(T) (Probe.at_temperature)."""
        return tuple(p.probe.at_temperature(self.temperature_k) for p in self.placed)

    def _hold_moment(self) -> None:
        """Take the moments at the present temperature and hold them until the cycle's next phase
        (the probes turned, the coils on, the coils off), in the potential, the coils' torque,
        the coupling and the fluxgates' pickup. A phase lasts ~0.5 s: the temperature moves by
        its rate × 0.5 s, a few mK in a warming lab, a relative change of the moment ~1e-6,
        below what one ring-down resolves; taken at the switch-off, the ring-down sees the moment
        of its own start. The spring, whose drift the kernel follows continuously, is not scaled."""
        magnets = self._magnets_now()
        if magnets != self._magnets:
            self._magnets = magnets
            self._build_series()

    def coils_off(self) -> None:
        """Every coil off from this sample on."""
        self._hold_moment()
        self._drive_off_index = min(self._drive_off_index, self.sample_index)

    def pluck(self, theta_rad: ArrayLike, theta_dot_rad_per_s: ArrayLike = 0.0) -> None:
        """Set the deflection states directly, one per probe (simulation only: plucked cantilevers)."""
        theta = self._deflections("theta_rad", theta_rad)
        theta_dot = np.broadcast_to(np.asarray(theta_dot_rad_per_s, float), theta.shape)
        if not np.all(np.isfinite(theta_dot)):
            raise ValueError(f"theta_dot_rad_per_s = {theta_dot_rad_per_s!r} must be finite")
        modes = [contact_mode(a, r, self._table, i) for i, (a, r) in enumerate(zip(theta, theta_dot))]
        self._state[:] = theta, theta_dot, modes

    def ring_down(self, start_rad: ArrayLike, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
        """The probes plucked from rest at ``start_rad`` (N,) ringing down freely: θ and θ'
        (n_samples, N) at the next samples, the first at the start."""
        start = self._deflections("start_rad", start_rad)
        if not (isinstance(n_samples, (int, np.integer)) and n_samples > 0):
            raise ValueError(f"n_samples = {n_samples!r} must be a whole number > 0")
        self.pluck(start)
        return self.integrate(n_samples)

    def _deflections(self, name: str, value: ArrayLike) -> np.ndarray:
        """``value`` as one deflection per probe within the potential's interval; ValueError naming ``name``."""
        count = len(self.placed)
        theta = np.asarray(value, float).reshape(-1)
        if theta.shape != (count,) or not np.all(np.abs(theta) < self.half_width_rad):
            raise ValueError(
                f"{name} = {value!r} must give one deflection per probe ({count}), "
                f"each within ±{self.half_width_rad:.3f} rad"
            )
        return theta

    # --- running -------------------------------------------------------------------------
    def equation_of_motion(self, amplitudes_a=None, frequency_hz: float = 0.0, drive_t0_s: float = 0.0):
        """rhs(t, [θ_1 … θ_N, θ'_1 … θ'_N]) → [θ', θ''] at the present poses, for other
        integrators (solve_ivp).

        Coil k carries amplitudes_a[k]·sin(2πf·(t − drive_t0_s)). The stop's contact mode is
        read from the state at each call, without the event location of the kernel.
        """
        amplitudes = np.zeros((0, self.n_coils)) if amplitudes_a is None else np.reshape(amplitudes_a, (1, -1))
        drive, omegas = self._drive_of(np.asarray(amplitudes, float), np.full(len(amplitudes), math.tau * frequency_hz))
        table, count = kernel_table(self._head, self._env_series, drive, omegas), len(self.placed)

        def rhs(t, y):
            theta, omega = np.asarray(y[:count], float), np.asarray(y[count:], float)
            mode = np.array([contact_mode(a, r, table, i) for i, (a, r) in enumerate(zip(theta, omega))])
            acceleration = accelerations(theta, omega, t, mode, table, drive_t0_s, len(omegas))
            return np.concatenate([omega, acceleration])

        return rhs

    def coupling_torque_nm(self, theta_rad: ArrayLike) -> np.ndarray:
        """(N,): τ_i, the torque of the other magnets on each probe at deflections ``theta_rad``
        (:mod:`mows.sim.kernel`)."""
        return coupling_torques(np.asarray(theta_rad, float), self._table)

    def integrate(self, n_samples: int) -> tuple[np.ndarray, np.ndarray]:
        """Advance the probes by ``n_samples`` without reading the sensors: θ and θ' (n, N) at the samples."""
        if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 0):
            raise ValueError(f"n_samples = {n_samples!r} must be an integer ≥ 0")
        count = len(self.placed)
        theta, theta_dot = np.empty((n_samples, count)), np.empty((n_samples, count))
        integrator = self.scenario.integrator
        done = 0
        while done < n_samples:
            # The drive switches at its on and off samples: the stretches between are integrated apart.
            index = self.sample_index
            driven = self._drive_on_index <= index < self._drive_off_index
            switch = self._drive_off_index if driven else self._drive_on_index
            stretch = n_samples - done if switch <= index else min(n_samples - done, switch - index)
            finished = advance(
                self._state,
                self._table,
                index,
                self.sample_rate_hz,
                integrator.substeps,
                integrator.contact_substeps,
                self._drive_on_index / self.sample_rate_hz,
                len(self._drive_omegas) if driven else 0,
                theta[done : done + stretch],
                theta_dot[done : done + stretch],
            )
            self.sample_index += finished
            done += finished
            if finished < stretch:
                raise RuntimeError(
                    f"a deflection θ = {self._state[0]} rad left the interval ±{self.half_width_rad:.3f} rad on "
                    "which the potential is represented: lower the drive's amplitude"
                )
        return theta, theta_dot

    def idle(self, duration_s: float, chunk_samples: int = 20_000) -> None:
        """Let ``duration_s`` of device time pass unrecorded (the gap between repeats): the probes
        move, the sensors are not read, so the noise stream resumes where it stopped."""
        remaining = int(round(duration_s * self.sample_rate_hz))
        while remaining > 0:
            remaining -= len(self.integrate(min(remaining, chunk_samples))[0])

    def currents_at(self, sample_indices: ArrayLike) -> np.ndarray:
        """Coil currents at ``sample_indices`` under the present drive, A, shape (n, n_coils)."""
        index = np.asarray(sample_indices)
        t = index / self.sample_rate_hz
        carriers = np.sin(np.multiply.outer(t - self._drive_on_index / self.sample_rate_hz, self._tone_omegas))
        on = (index >= self._drive_on_index) & (index < self._drive_off_index)
        return np.where(on[:, None], carriers @ self._tone_amplitudes_a, 0.0)

    def read(self, n_samples: int) -> SimulatedBlock:
        """The next ``n_samples`` samples of both fluxgates; the probes keep moving afterwards."""
        first = self.sample_index
        index = first + np.arange(n_samples)
        currents = self.currents_at(index)
        coils_on = (index >= self._drive_on_index) & (index < self._drive_off_index)
        theta, theta_dot = self.integrate(n_samples)
        magnets = [PlacedProbe(m, p.pose) for m, p in zip(self._magnets, self.placed)]
        field = (
            swinging_pickup_t(self._pair, magnets, theta)
            + self._env_reading_t
            + currents @ self._coil_reading_t_per_a
            + self._noise.draw(first, n_samples)
        )
        readings, saturated = self._pair.digitise(field)
        samples = SampleBlock(
            first, round(first * NS_PER_S / self.sample_rate_hz), self.sample_rate_hz, readings, saturated
        )
        return SimulatedBlock(samples, coils_on, theta, theta_dot, currents)

    # --- truth ---------------------------------------------------------------------------
    @property
    def temperature_k(self) -> float:
        return float(self.scenario.environment.temperature_at(self.sample_index / self.sample_rate_hz))

    def potentials(self) -> tuple[ArcPotential, ...]:
        """U(θ) of each probe at its present pose and the present temperature, in the static
        field and, with several, its neighbours' dipoles at their coupled rest
        (:func:`mows.physics.coupling.coupled_rest`)."""
        magnets = [PlacedProbe(m, p.pose) for m, p in zip(self._magnets, self.placed)]
        source, temperature_k = self.static_source, self.temperature_k
        if len(magnets) == 1:
            sources = [source]
        else:
            rest = coupled_rest(magnets, source, temperature_k)
            sources = [external_source(rest, source, i) for i in range(len(magnets))]
        return tuple(
            ArcPotential.from_source(p.probe, s, p.pose, temperature_k, half_width_rad=self.half_width_rad)
            for p, s in zip(magnets, sources)
        )

    def potential(self, probe: int = 0) -> ArcPotential:
        """U(θ) of probe ``probe`` (:meth:`potentials`)."""
        return self.potentials()[probe]

    def expected_frequencies_hz(self, amplitude_rad: float = 0.0) -> np.ndarray:
        """(N,): each probe's ring-down frequency at swing ``amplitude_rad`` from its full potential
        (harmonic balance, Eq. S1; with several, in its neighbours' fields, :meth:`potentials`)."""
        return np.array([float(p.frequency_hz(amplitude_rad)) for p in self.potentials()])

    def expected_frequency_hz(self, amplitude_rad: float = 0.0, probe: int = 0) -> float:
        """The ring-down frequency of probe ``probe`` at swing ``amplitude_rad`` (:meth:`expected_frequencies_hz`)."""
        return float(self.potential(probe).frequency_hz(amplitude_rad))

    @property
    def truth(self) -> DeviceTruth:
        potentials = self.potentials()
        where = np.array([p.pose.magnet_position_m for p in self.placed], float)
        return DeviceTruth(
            time_s=self.sample_index / self.sample_rate_hz,
            theta0_rad=self.theta0_rad,
            theta_rad=self._state[0].copy(),
            theta_dot_rad_per_s=self._state[1].copy(),
            rest_angle_rad=np.array([float(p.rest_angle_rad()) for p in potentials]),
            temperature_k=self.temperature_k,
            spring_nm_per_rad=np.array([p.probe.spring_at(self.temperature_k) for p in self.placed]),
            field_t=self.static_source.field_t(where),
            gradient_t_per_m=self.static_source.gradient_t_per_m(where),
            potentials=potentials,
        )
