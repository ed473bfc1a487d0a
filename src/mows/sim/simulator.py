"""The simulated MOWS device (:class:`SimulatedDevice`) with every probe of its scene, sample by
sample like the hardware (docs/physics.md §2, §4; docs/multi_probe.md). One probe is a scene of one.

It integrates the probes' motion together with the kernels of :mod:`mows.sim.kernel` (equation
of motion, the neighbours' coupling, housing stop, integrator and its step error are described
there) and reads the two fluxgates with the noise of :mod:`mows.sim.noise`; the driver's measurement
cycle runs on it in device time (:mod:`mows.device.stream.simulated_cycle`).

Drive. The coils carry tones (:meth:`SimulatedDevice.drive`): per tone a signed amplitude per
coil at one frequency, summed, from the sample they switch on to the sample they switch off. One
probe's drive is one tone, the current scheme of :class:`mows.physics.coils.CoilSetup`; several
probes' are the sum of theirs (:func:`mows.physics.multitone.coil_amplitudes_a`).

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

import numpy as np
from numpy.typing import ArrayLike

from mows.physics.coupling import PlacedProbe, coupled_rest
from mows.physics.field import SumSource
from mows.physics.multitone import summed_peak_a
from mows.physics.potential import DEFAULT_HALF_WIDTH_RAD, ArcPotential
from mows.records.samples import SampleBlock
from mows.records.stamps import NS_PER_S
from mows.sim.kernel import (
    G_LEVER,
    G_MOMENT,
    G_PIVOT,
    G_X_AXIS,
    G_Y_AXIS,
    accelerations,
    advance,
    check_resolvable,
    contact_mode,
    coupling_torques,
    kernel_table,
    probe_parameters,
)
from mows.sim.noise import NoiseStream
from mows.sim.readings import DeviceTruth, SimulatedBlock, swinging_pickup_t

# The Chebyshev interval covers the stop with room for the contact's penetration.
INTERVAL_OVER_STOP = 1.5
# Chebyshev terms below this fraction of kM·w (N·m) are dropped from the kernel's series.
SERIES_TOLERANCE = 1e-15
# The off sample of a drive that runs until it is switched off.
NEVER = 2**62


def slope_series(magnets, poses, static_source, driven_sources, half_width_rad: float) -> tuple[list, list]:
    """The Chebyshev coefficients of W'(θ) of each of ``magnets`` at its pose, the negligible
    tail dropped: in ``static_source`` with gravity's torque, [probe]; and in each of
    ``driven_sources`` (a coil's or the supply's field per ampere) without it, [source][probe]."""
    weightless = [dataclasses.replace(pose, gravity_m_per_s2=(0.0, 0.0, 0.0)) for pose in poses]

    def series(magnet, source, pose) -> np.ndarray:
        coeffs = ArcPotential.from_source(magnet, source, pose, half_width_rad=half_width_rad).d1
        significant = np.flatnonzero(np.abs(coeffs) > SERIES_TOLERANCE * magnet.spring_nm_per_rad * half_width_rad)
        return np.ascontiguousarray(coeffs[: max(2, significant[-1] + 1 if significant.size else 2)])

    static = [series(m, static_source, pose) for m, pose in zip(magnets, poses)]
    return static, [[series(m, source, pose) for m, pose in zip(magnets, weightless)] for source in driven_sources]


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
        check_resolvable(self.placed, self.static_source, scenario.integrator.substeps, self.sample_rate_hz)
        self._head = probe_parameters(
            [p.probe for p in self.placed], scenario.environment, scenario.housing, self.half_width_rad
        )
        self._tone_amplitudes_a = np.zeros((0, self.n_coils))  # (tones, coils)
        self._tone_omegas = np.zeros(0)
        self._drive_series, self._drive_omegas = np.zeros((0, len(self.placed), 0)), np.zeros(0)
        self._drive_on_index = self._drive_off_index = 0
        self._state = np.zeros((3, len(self.placed)))  # θ, θ', contact mode of each probe
        self.set_orientations([p.pose.theta0_rad for p in self.placed] if theta0_rad is None else theta0_rad)
        self._state[0] = self.truth.rest_angle_rad

    # --- set-up --------------------------------------------------------------------------
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
        supply = () if self._supply is None else (self._supply.source,)
        self._fixed_series, driven = slope_series(
            self._magnets, poses, self._fixed_source, (*self.setup.coils, *supply), self.half_width_rad
        )
        self._coil_series = driven[: self.n_coils]  # [coil][probe]
        self._supply_series = driven[self.n_coils] if supply else [np.zeros(0) for _ in poses]
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

    def drive(self, amplitudes_a: ArrayLike, frequencies_hz: ArrayLike, off_index: int = NEVER) -> None:
        """The coils carry tones from this sample (t_on) until sample ``off_index`` (exclusive; by
        default until :meth:`coils_off`): coil c carries Σ_k amplitudes_a[k][c]·sin(2π·f_k·(t − t_on)),
        one row of signed coil amplitudes (K, n_coils) per tone at ``frequencies_hz`` (K,). One
        probe's drive is one tone; the tones of probes are
        :func:`mows.physics.multitone.coil_amplitudes_a`.

        ValueError if the count of coils is not ``n_coils``, a frequency is not in (0, fs/2) or
        the tones' summed peak over the span (:func:`mows.physics.multitone.summed_peak_a`)
        exceeds the setup's cap.
        """
        amplitudes = np.asarray(amplitudes_a, float)
        frequencies = np.asarray(frequencies_hz, float).reshape(-1)
        if amplitudes.ndim != 2 or amplitudes.shape[1] != self.n_coils or len(amplitudes) != len(frequencies):
            raise ValueError(
                f"amplitudes_a {amplitudes.shape} must give one row of {self.n_coils} coils (the setup's) "
                f"for each of the {len(frequencies)} frequencies"
            )
        off = int(off_index)
        if not len(frequencies) or off <= self.sample_index:
            raise ValueError(
                f"drive: tones {frequencies_hz!r} until sample {off_index!r} must be some tones over a later span"
            )
        nyquist_hz = self.sample_rate_hz / 2.0
        if not np.all(np.isfinite(frequencies) & (frequencies > 0.0) & (frequencies < nyquist_hz)):
            raise ValueError(
                f"frequencies_hz = {frequencies_hz!r}: each frequency_hz must be in (0, {nyquist_hz:g}) Hz"
            )
        duration_s = math.inf if off == NEVER else (off - self.sample_index) / self.sample_rate_hz
        self.setup.cap.check(summed_peak_a(amplitudes, frequencies, duration_s))
        self._hold_moment()
        self._tone_amplitudes_a = amplitudes
        self._tone_omegas = math.tau * frequencies
        self._drive_on_index, self._drive_off_index = self.sample_index, off
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
    def equation_of_motion(self, amplitudes_a: ArrayLike = (), frequencies_hz: ArrayLike = (), drive_t0_s: float = 0.0):
        """rhs(t, [θ_1 … θ_N, θ'_1 … θ'_N]) → [θ', θ''] at the present poses, for other
        integrators (solve_ivp).

        The coils carry the tones of :meth:`drive` (none by default), from ``drive_t0_s``. The
        stop's contact mode is read from the state at each call, without the event location of
        the kernel.
        """
        amplitudes = np.asarray(amplitudes_a, float).reshape(-1, self.n_coils)
        drive, omegas = self._drive_of(amplitudes, math.tau * np.asarray(frequencies_hz, float).reshape(-1))
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
        field and its neighbours' dipoles where they rest (:func:`mows.physics.coupling.coupled_rest`)."""
        magnets = [PlacedProbe(m, p.pose) for m, p in zip(self._magnets, self.placed)]
        return coupled_rest(magnets, self.static_source, self.temperature_k, self.half_width_rad).potentials

    def expected_frequencies_hz(self, amplitude_rad: float = 0.0) -> np.ndarray:
        """(N,): each probe's ring-down frequency at swing ``amplitude_rad`` from its full potential
        (harmonic balance, Eq. S1; with several, in its neighbours' fields, :meth:`potentials`)."""
        return np.array([float(p.frequency_hz(amplitude_rad)) for p in self.potentials()])

    @property
    def truth(self) -> DeviceTruth:
        potentials = self.potentials()
        where = np.array([p.pose.magnet_position_m for p in self.placed], float)
        return DeviceTruth(
            time_s=self.sample_index / self.sample_rate_hz,
            theta0_rad=self.theta0_rad,
            theta_rad=self._state[0].copy(),
            theta_dot_rad_per_s=self._state[1].copy(),
            rest_angle_rad=np.array([float(p.settled_angle_rad()) for p in potentials]),
            temperature_k=self.temperature_k,
            spring_nm_per_rad=np.array([p.probe.spring_at(self.temperature_k) for p in self.placed]),
            field_t=self.static_source.field_t(where),
            gradient_t_per_m=self.static_source.gradient_t_per_m(where),
            potentials=potentials,
        )
