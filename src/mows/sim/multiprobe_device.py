"""The simulated device of a scene with several probes (:class:`MultiProbeDevice`), sample by
sample like :class:`mows.sim.simulator.SimulatedDevice` is for one.

Every probe of the scene (:attr:`mows.sim.scenario.Scenario.probes`) obeys the coupled equation
of motion of :mod:`mows.sim.multiprobe`,

    J_i·θ_i'' = −kM_i·θ_i − W_i'(θ_i) − Σ_c I_c(t)·W_ic'(θ_i) − 2J_i·δ_i·θ_i' + τ_i,

with W_i the energy of probe i's magnet on its arc in the scene's static field and gravity,
W_ic that of coil c per ampere (both exact on the arc, as Chebyshev series:
:class:`mows.physics.potential.ArcPotential`), I_c(t) the multi-tone drive of the excitation's
tones (:func:`mows.physics.multitone.drive_currents_a`, from the sample it switched on) and τ_i
the torque of the other magnets' exact dipole fields at their current deflections: the static
coupling (the neighbours at rest) and the dynamic one (their swing) at once. All probes are
integrated together, RK4 with the scenario's ``substeps`` per sample, compiled (numba).

Not simulated for several probes: the housing stop (the drive's amplitude must keep every swing
within the potential's interval, else RuntimeError), the temperature's drift (the springs are
at the environment's starting temperature) and the field supply.

Fluxgates. Both sensors read the sum of every magnet's exact dipole field at its actual
position with its actual moment, the static field, the coils' fields × their currents and the
scenario's noise, offset-nulled, clipped and quantised as for one probe.

Stages. :meth:`MultiProbeDevice.set_orientations` turns each probe to its θ0 between
excitations (instantly on the device clock, the deflections carried along); a scene's probes on
the shared stage are turned by the caller with one angle added to their home orientations.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from mows.physics.coupling import coupled_frequencies_hz, coupled_rest
from mows.physics.multitone import Tone, coil_amplitudes_a, drive_currents_a, peak_current_a
from mows.physics.potential import DEFAULT_HALF_WIDTH_RAD, ArcPotential
from mows.records.samples import SampleBlock
from mows.records.stamps import NS_PER_S
from mows.sim.multiprobe import _coupling_torques_into, swinging_pickup_t
from mows.sim.noise import NoiseStream
from mows.sim.simulator import INTERVAL_OVER_STOP

TWO_PI = 2.0 * math.pi


@dataclasses.dataclass(frozen=True, eq=False)
class MultiProbeBlock:
    """What the device read (``samples``, column 0 the near sensor) and the simulation's truth at
    those samples: ``coils_on`` (n,), each probe's deflection ``theta_rad`` (n, N) and the coil
    currents ``currents_a`` (n, n_coils)."""

    samples: SampleBlock
    coils_on: np.ndarray
    theta_rad: np.ndarray
    currents_a: np.ndarray

    def __len__(self) -> int:
        return len(self.samples)


class MultiProbeDevice:
    """The device of ``scenario`` with all of its probes (module docstring), starting at rest in
    their coupled rest angles at their home orientations. ``rng`` defaults to
    ``numpy.random.default_rng(scenario.seed)``."""

    def __init__(self, scenario, rng: np.random.Generator | None = None):
        self.scenario = scenario
        self.placed = tuple(scenario.placed_probes())
        self.setup = scenario.setup
        self.sample_rate_hz = float(scenario.sample_rate_hz)
        self.sample_index = 0
        self.source = scenario.environment.source
        self._noise = NoiseStream(
            scenario.noise, self.sample_rate_hz, np.random.default_rng(scenario.seed) if rng is None else rng
        )
        pair = scenario.sensors.pair
        at_sensors = self.source.field_t(pair.positions_m)
        self._pair = pair.with_offsets_nulled(at_sensors) if scenario.sensors.null_offsets else pair
        self._static_reading_t = self._pair.component_t(at_sensors)
        coil_fields = self.setup.coil_field_per_ampere_t(pair.positions_m)  # (2, C, 3)
        self._coil_reading_t_per_a = np.stack(
            [self._pair.component_t(coil_fields[:, c]) for c in range(len(self.setup.coils))]
        )  # (C, 2)
        stops = [p.probe.theta_stop_rad for p in self.placed]
        self.half_width_rad = max(DEFAULT_HALF_WIDTH_RAD, INTERVAL_OVER_STOP * max(stops))
        probes = [p.probe for p in self.placed]
        temperature_k = scenario.environment.temperature_k
        self._spring = np.array([p.spring_at(temperature_k) for p in probes])
        self._inv_inertia = np.array([1.0 / p.inertia_kgm2 for p in probes])
        self._two_delta = np.array([2.0 * p.damping_per_s for p in probes])
        self._moment = np.array([p.moment_am2 for p in probes])
        self._lever = np.array([p.lever_m for p in probes])
        self._tones: tuple[Tone, ...] = ()
        self._tone_amplitudes_a = np.zeros((0, len(self.setup.coils)))
        self._tone_omegas = np.zeros(0)
        self._drive_on_index = 0
        self._drive_off_index = 0
        self.set_orientations([p.pose.theta0_rad for p in self.placed])
        self._theta = coupled_rest(self.placed, self.source, temperature_k).rest_angle_rad.copy()
        self._omega = np.zeros(len(self.placed))

    # --- set-up --------------------------------------------------------------------------
    @property
    def coils_on(self) -> bool:
        return self._drive_on_index <= self.sample_index < self._drive_off_index

    @property
    def n_coils(self) -> int:
        return len(self.setup.coils)

    @property
    def theta0_rad(self) -> np.ndarray:
        return np.array([p.pose.theta0_rad for p in self.placed])

    def set_orientations(self, theta0_rad: ArrayLike) -> None:
        """Each probe's stage turns it to its θ0 (N,). RuntimeError while the coils are on."""
        if self.coils_on:
            raise RuntimeError("set_orientations: the coils are on; turn the probes between excitations")
        angles = np.asarray(theta0_rad, float)
        if angles.shape != (len(self.placed),) or not np.all(np.isfinite(angles)):
            raise ValueError(f"theta0_rad = {theta0_rad!r} must give one finite angle per probe ({len(self.placed)})")
        self.placed = tuple(self.scenario.placed_probes(angles))
        axes = [p.pose.axes() for p in self.placed]
        self._x_axis = np.array([a[0] for a in axes])
        self._y_axis = np.array([a[1] for a in axes])
        self._pivot = np.array([p.pose.pivot_m(p.probe.lever_m) for p in self.placed])
        self._env_series = np.array([self._slope_series(p.probe, self.source, p.pose) for p in self.placed])
        self._coil_series = np.array(
            [
                [
                    self._slope_series(p.probe, coil, dataclasses.replace(p.pose, gravity_m_per_s2=(0.0, 0.0, 0.0)))
                    for p in self.placed
                ]
                for coil in self.setup.coils
            ]
        )  # (C, N, nodes)

    def _slope_series(self, probe, source, pose) -> np.ndarray:
        """Chebyshev coefficients of W'(θ) (x = θ/w) of ``probe`` at ``pose`` in ``source``."""
        return ArcPotential.from_source(probe, source, pose, half_width_rad=self.half_width_rad).d1

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
        self._tones = tuple(tones)
        self._tone_amplitudes_a = coil_amplitudes_a(self.setup, self._tones)
        self._tone_omegas = TWO_PI * np.array([t.frequency_hz for t in self._tones])
        self._drive_on_index, self._drive_off_index = self.sample_index, off

    def emergency_stop(self) -> None:
        """Every tone off from this sample on."""
        self._drive_off_index = min(self._drive_off_index, self.sample_index)

    # --- running -------------------------------------------------------------------------
    def currents_at(self, sample_indices: ArrayLike) -> np.ndarray:
        """(n, n_coils): the coil currents at ``sample_indices``, A."""
        index = np.asarray(sample_indices, dtype=np.int64)
        currents = np.zeros((index.size, len(self.setup.coils)))
        on = (index >= self._drive_on_index) & (index < self._drive_off_index)
        if self._tones and np.any(on):
            times = (index[on] - self._drive_on_index) / self.sample_rate_hz
            currents[on] = drive_currents_a(self.setup, self._tones, times)
        return currents

    def integrate(self, n_samples: int) -> np.ndarray:
        """Advance every probe by ``n_samples`` without reading the sensors: θ (n, N)."""
        if not (isinstance(n_samples, (int, np.integer)) and n_samples >= 0):
            raise ValueError(f"n_samples = {n_samples!r} must be an integer ≥ 0")
        theta = np.empty((n_samples, len(self.placed)))
        done = 0
        while done < n_samples:
            # The drive switches at its on and off samples: integrate the stretches between apart.
            index = self.sample_index
            driven = self._drive_on_index <= index < self._drive_off_index
            switch = self._drive_off_index if driven else self._drive_on_index
            count = n_samples - done if switch <= index else min(n_samples - done, switch - index)
            amplitudes = self._tone_amplitudes_a if driven else np.zeros((0, len(self.setup.coils)))
            omegas = self._tone_omegas if driven else np.zeros(0)
            finished = _advance(
                self._theta,
                self._omega,
                self.sample_index,
                count,
                self.sample_rate_hz,
                self.scenario.integrator.substeps,
                1.0 / self.half_width_rad,
                self._spring,
                self._inv_inertia,
                self._two_delta,
                self._env_series,
                self._coil_series,
                amplitudes,
                omegas,
                self._drive_on_index / self.sample_rate_hz,
                self._moment,
                self._lever,
                self._pivot,
                self._x_axis,
                self._y_axis,
                theta[done : done + count],
            )
            self.sample_index += finished
            done += finished
            if finished < count:
                raise RuntimeError(
                    f"a probe's deflection left ±{self.half_width_rad:.3f} rad, the interval on which its "
                    "potential is represented: lower the drive's amplitude"
                )
        return theta

    def idle(self, duration_s: float, chunk_samples: int = 20_000) -> None:
        """Let ``duration_s`` of device time pass unrecorded (the probes move, nobody reads)."""
        remaining = int(round(duration_s * self.sample_rate_hz))
        while remaining > 0:
            remaining -= len(self.integrate(min(remaining, chunk_samples)))

    def read(self, n_samples: int) -> MultiProbeBlock:
        """The next ``n_samples`` samples of both fluxgates; the probes keep moving afterwards."""
        first = self.sample_index
        index = first + np.arange(n_samples)
        currents = self.currents_at(index)
        coils_on = (index >= self._drive_on_index) & (index < self._drive_off_index)
        theta = self.integrate(n_samples)
        field = self._static_reading_t + currents @ self._coil_reading_t_per_a + self._noise.draw(first, n_samples)
        field = field + swinging_pickup_t(self._pair, self.placed, theta)
        readings, saturated = self._pair.digitise(field)
        samples = SampleBlock(
            first, round(first * NS_PER_S / self.sample_rate_hz), self.sample_rate_hz, readings, saturated
        )
        return MultiProbeBlock(samples, coils_on, theta, currents)

    # --- truth ---------------------------------------------------------------------------
    def expected_frequencies_hz(self, amplitude_rad: float = 0.0) -> np.ndarray:
        """(N,): each probe's first-principles frequency in the scene and its neighbours'
        fields at the present orientations (:func:`mows.physics.coupling.coupled_frequencies_hz`)."""
        return coupled_frequencies_hz(self.placed, self.source, amplitude_rad, self.scenario.environment.temperature_k)

    def external_field_t(self) -> tuple[np.ndarray, np.ndarray]:
        """The scene's field (N, 3), T, and gradient (N, 3, 3), T/m, at each magnet's rest
        position: what a decomposition should return, without the neighbours."""
        where = np.array([p.pose.magnet_position_m for p in self.placed])
        return self.source.field_t(where), self.source.gradient_t_per_m(where)


@njit(cache=True)
def _acceleration(
    theta, omega, t, inv_width, spring, inv_inertia, two_delta, env, coil, amplitudes, omegas, t_on, moment, lever,
    pivot, x_axis, y_axis, currents, axes, out,
):  # fmt: skip
    """θ'' of every probe (module docstring) at (θ, θ', t) into ``out``; ``currents`` (n_coils,)
    and ``axes`` (N, 6) are scratch. Without tones the coils' series are skipped (their currents are zero)."""
    driven = omegas.size > 0
    for c in range(coil.shape[0]):
        currents[c] = 0.0
    for tone in range(omegas.size):
        carrier = math.sin(omegas[tone] * (t - t_on))
        for c in range(coil.shape[0]):
            currents[c] += amplitudes[tone, c] * carrier
    _coupling_torques_into(theta, moment, lever, pivot, x_axis, y_axis, axes, out)
    for i in range(theta.size):
        x = theta[i] * inv_width
        t_prev, t_cur = 1.0, x
        slope = env[i, 0] + env[i, 1] * x
        if driven:
            for c in range(coil.shape[0]):
                slope += currents[c] * (coil[c, i, 0] + coil[c, i, 1] * x)
        for j in range(2, env.shape[1]):
            t_prev, t_cur = t_cur, 2.0 * x * t_cur - t_prev
            slope += env[i, j] * t_cur
            if driven:
                for c in range(coil.shape[0]):
                    slope += currents[c] * coil[c, i, j] * t_cur
        out[i] = (out[i] - spring[i] * theta[i] - slope) * inv_inertia[i] - two_delta[i] * omega[i]


@njit(cache=True, nogil=True)  # the driver's executor answers requests while it runs
def _advance(
    theta, omega, first_index, n, fs, substeps, inv_width, spring, inv_inertia, two_delta, env, coil, amplitudes,
    omegas, t_on, moment, lever, pivot, x_axis, y_axis, out,
):  # fmt: skip
    """RK4 over ``n`` samples from ``first_index``, θ at each sample into ``out``; the state
    (θ, θ') is updated in place. Returns the samples done: fewer when a deflection leaves the
    interval ±w, where the potential's series ends. The stages' states and accelerations live in
    arrays made once, not per substep."""
    h = 1.0 / (fs * substeps)
    count = theta.size
    currents, axes = np.empty(coil.shape[0]), np.empty((count, 6))
    a1, a2, a3, a4 = np.empty(count), np.empty(count), np.empty(count), np.empty(count)
    stage_theta, stage_omega = np.empty(count), np.empty(count)
    args = (inv_width, spring, inv_inertia, two_delta, env, coil, amplitudes, omegas, t_on, moment, lever, pivot,
            x_axis, y_axis, currents, axes)  # fmt: skip
    for sample in range(n):
        for i in range(count):
            if abs(theta[i]) * inv_width >= 1.0:
                return sample
        out[sample] = theta
        t = (first_index + sample) / fs
        for step in range(substeps):
            ts = t + step * h
            _acceleration(theta, omega, ts, *args, a1)
            for i in range(count):
                stage_theta[i] = theta[i] + 0.5 * h * omega[i]
                stage_omega[i] = omega[i] + 0.5 * h * a1[i]
            _acceleration(stage_theta, stage_omega, ts + 0.5 * h, *args, a2)
            for i in range(count):
                stage_theta[i] = theta[i] + 0.5 * h * (omega[i] + 0.5 * h * a1[i])
                stage_omega[i] = omega[i] + 0.5 * h * a2[i]
            _acceleration(stage_theta, stage_omega, ts + 0.5 * h, *args, a3)
            for i in range(count):
                stage_theta[i] = theta[i] + h * (omega[i] + 0.5 * h * a2[i])
                stage_omega[i] = omega[i] + h * a3[i]
            _acceleration(stage_theta, stage_omega, ts + h, *args, a4)
            for i in range(count):
                theta[i] = theta[i] + h * omega[i] + h * h / 6.0 * (a1[i] + a2[i] + a3[i])
                omega[i] = omega[i] + h / 6.0 * (a1[i] + 2.0 * a2[i] + 2.0 * a3[i] + a4[i])
    return n
