"""Synthetic measurement tables from independent physics (the lab's test data).

The truth never comes from the lab's own model. For every row:

1. the **exact** field of real sources (:mod:`mows.physics.field`: uniform fields, dipoles, current
   loops, Helmholtz and anti-Helmholtz pairs, solenoids) is sampled along the lever's actual
   arc, with the actual pose (θ0, gravity of a tilted plane) and the spring at the row's
   temperature: W(θ) of :func:`mows.physics.potential.arc_energy_j`, as
   :meth:`mows.physics.potential.ArcPotential.from_source` does, batched over the rows;
2. the ring-down frequency is the damped harmonic-balance frequency √(k(A)/J − δ²)/2π
   averaged over the decaying ring-down as the constant-frequency estimator sees it
   (:mod:`mows.physics.ringdown_average`, here with 8 Gauss nodes where the lab uses 3);
3. Gaussian noise of ``f_std_hz`` is added with the caller's generator.

The reference columns are the true field and in-plane gradient at the probe (of ``reference``
when given: a reference that misses a source), optionally with magnetometer noise.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence

import numpy as np

from mows.device.stream.simulated_cycle import CycleRecord, simulate_cycle
from mows.estimate.recorded_cycle import fit_cycle
from mows.estimate.ringdown import COIL_OFF_SKIP_S
from mows.lab.data.reference import reference_columns
from mows.lab.data.table import FIELD, GRADIENT, MAGNET, PROBE, MeasurementTable
from mows.physics import ringdown_average
from mows.physics.coupling import PlacedProbe, coupled_rest, external_source
from mows.physics.field import FieldSource
from mows.physics.pose import STANDARD_GRAVITY_M_PER_S2, Pose
from mows.physics.potential import ArcPotential, arc_energy_j, chebyshev_nodes_rad
from mows.physics.probe import Probe
from mows.physics.schema import FloatOrArray, Vector
from mows.sim.scenario import Scenario
from mows.sim.simulator import SimulatedDevice
from mows.sweep.record import SweepPoint, SweepRecord

TRUTH_NODES = 8
LEVEL = (0.0, 0.0, -STANDARD_GRAVITY_M_PER_S2)


def _per_row(sources: FieldSource | Iterable[FieldSource], n: int) -> list[FieldSource]:
    if isinstance(sources, FieldSource):
        return [sources] * n
    sources = list(sources)
    if len(sources) != n:
        raise ValueError(f"got {len(sources)} field sources for {n} rows")
    return sources


def true_frequency_hz(
    probe: Probe,
    sources: FieldSource | Iterable[FieldSource],
    theta0_rad: FloatOrArray,
    amplitude_start_rad: FloatOrArray,
    temperature_k: FloatOrArray | None = None,
    gravity_m_per_s2: Vector = LEVEL,
    magnet_position_m: Vector = (0.0, 0.0, 0.0),
    duration_s: FloatOrArray | None = None,
) -> np.ndarray:
    """Noise-free ring-down frequencies (n,), Hz, from the exact sources (module docstring).

    ``sources``: one :class:`~mows.physics.field.FieldSource` or one per row. Per-row arguments broadcast
    to (n,); ``duration_s`` defaults to 60 periods. At ``temperature_k`` the spring and the
    magnet's moment follow the probe's coefficients (:meth:`Probe.spring_at`, :meth:`Probe.at_temperature`).
    """
    theta0 = np.atleast_1d(np.asarray(theta0_rad, float))
    n = len(theta0)
    rows = _per_row(sources, n)
    nodes = chebyshev_nodes_rad()
    kelvin = [None] * n if temperature_k is None else np.broadcast_to(np.asarray(temperature_k, float), (n,))
    energy = np.stack(
        [
            arc_energy_j(
                probe if t_k is None else probe.at_temperature(float(t_k)),
                source,
                Pose(
                    magnet_position_m=tuple(magnet_position_m),
                    theta0_rad=float(t),
                    gravity_m_per_s2=tuple(gravity_m_per_s2),
                ),
                nodes,
            )
            for source, t, t_k in zip(rows, theta0, kelvin)
        ]
    )
    spring = (
        probe.spring_nm_per_rad
        if temperature_k is None
        else probe.spring_at(np.broadcast_to(np.asarray(temperature_k, float), (n,)))
    )
    small = ArcPotential(spring, probe.inertia_kgm2, probe.damping_per_s, energy).frequency_hz(0.0)
    duration = ringdown_average.default_duration_s(small) if duration_s is None else duration_s
    amplitudes, weights = ringdown_average.amplitude_nodes(
        theta0, amplitude_start_rad, probe.damping_per_s, duration, nodes=TRUTH_NODES
    )
    batch = ArcPotential(
        np.repeat(np.broadcast_to(spring, (n,)), TRUTH_NODES),
        probe.inertia_kgm2,
        probe.damping_per_s,
        np.repeat(energy, TRUTH_NODES, axis=0),
    )
    return (weights * batch.frequency_hz(amplitudes.reshape(-1)).reshape(n, TRUTH_NODES)).sum(-1)


def synthesize(
    probe: Probe,
    sources: FieldSource | Iterable[FieldSource],
    theta0_deg: FloatOrArray,
    rng: np.random.Generator,
    f_std_hz: FloatOrArray = 1e-3,
    amplitude_deg: FloatOrArray | None = None,
    temperature_k: FloatOrArray | None = None,
    gravity_m_per_s2: Vector = LEVEL,
    magnet_position_m: Vector = (0.0, 0.0, 0.0),
    reference: FieldSource | Iterable[FieldSource] | None = None,
    reference_noise_t: float = 0.0,
    truth_hz: np.ndarray | None = None,
    **columns: FloatOrArray,
) -> MeasurementTable:
    """A measurement table: true frequencies plus noise, and reference columns.

    Parameters
    ----------
    probe : the true probe.
    sources : the true field source, or one per row.
    theta0_deg : orientations (n,).
    rng : generator for the frequency (and reference) noise.
    f_std_hz : noise of each frequency, written to ``f_std_hz``.
    amplitude_deg : start amplitude of each ring-down (default: the housing stop), written to
        ``amplitude_deg``.
    temperature_k : per-row temperature, written to ``temperature_k`` when given.
    gravity_m_per_s2 : global gravity (a tilted plane has an in-plane component).
    reference : the source the reference magnetometer sees (default: ``sources``).
    reference_noise_t : Gaussian noise added to the reference field columns.
    truth_hz : precomputed :func:`true_frequency_hz` (to redraw noise cheaply).
    columns : further columns (``t_s``, ``sweep``, ``coil_current_a``, covariates …).
    """
    theta0 = np.radians(np.asarray(theta0_deg, float))
    n = len(theta0)
    amplitude = np.broadcast_to(probe.theta_stop_rad if amplitude_deg is None else np.radians(amplitude_deg), (n,))
    if truth_hz is None:
        truth_hz = true_frequency_hz(
            probe, sources, theta0, amplitude, temperature_k, gravity_m_per_s2, magnet_position_m
        )
    std = np.broadcast_to(np.asarray(f_std_hz, float), (n,))
    table = {
        "theta0_deg": np.degrees(theta0),
        "f_hz": truth_hz + rng.normal(0.0, 1.0, n) * std,
        "f_std_hz": std.copy(),
        "amplitude_deg": np.degrees(amplitude),
    }
    point = np.asarray(magnet_position_m, float)
    seen = _per_row(sources if reference is None else reference, n)
    field = np.array([s.field_t(point) for s in seen]) + rng.normal(0.0, 1.0, (n, 3)) * reference_noise_t
    gradient = np.array([s.gradient_t_per_m(point) for s in seen])
    table.update(zip(FIELD, field.T))
    table.update(zip(GRADIENT, (gradient[:, 0, 0], gradient[:, 0, 1], gradient[:, 1, 1])))
    if temperature_k is not None:
        table["temperature_k"] = np.broadcast_to(np.asarray(temperature_k, float), (n,)).copy()
    table.update({name: np.broadcast_to(np.asarray(v, float), (n,)).copy() for name, v in columns.items()})
    return MeasurementTable(table, "synthetic")


def rotation_sweeps(step_deg: float = 10.0, sweeps: int = 2, seconds_per_row: float = 10.0) -> dict[str, np.ndarray]:
    """θ0 (deg), sweep number and time (s) of ``sweeps`` full rotations in steps of ``step_deg``."""
    angles = np.arange(0.0, 360.0, step_deg)
    theta0 = np.tile(angles, sweeps)
    return {
        "theta0_deg": theta0,
        "sweep": np.repeat(np.arange(sweeps), len(angles)).astype(float),
        "t_s": np.arange(len(theta0)) * seconds_per_row,
    }


def coupled_probes_table(
    placed: Sequence[PlacedProbe],
    scene: FieldSource,
    stage_deg: Vector,
    sweeps: int,
    rng: np.random.Generator,
    f_std_hz: float = 3.3e-4,
    amplitude_deg: float = 2.0,
    coupled: bool = True,
) -> MeasurementTable:
    """A table of several probes on one stage in ``scene``, from the coupled first-principles
    model (:mod:`mows.physics.coupling`).

    ``placed`` gives each probe's constants, its magnet's position and its orientation at stage
    angle 0 (``pose.theta0_rad``). Each sweep turns the stage through ``stage_deg``. At every
    step, every probe rings down in the scene plus its neighbours' exact dipoles at their
    self-consistent rest (:func:`mows.physics.coupling.coupled_rest`), or in the scene alone when
    ``coupled`` is False. The frequencies are :func:`true_frequency_hz` of ring-downs from
    ``amplitude_deg`` plus noise of ``f_std_hz``. The reference is the scene alone, and the
    columns ``probe`` (its index in ``placed``), ``step``, ``sweep``, ``t_s`` and the magnet's
    position say where and when each row was measured (:mod:`mows.lab.data.probe_rows`).
    """
    steps = np.tile(np.asarray(stage_deg, float), sweeps)
    sources: list[list[FieldSource]] = [[] for _ in placed]
    for stage_rad in np.radians(steps):
        turned = [dataclasses.replace(p, pose=p.pose.with_theta0(p.pose.theta0_rad + stage_rad)) for p in placed]
        state = coupled_rest(turned, scene) if coupled else None
        for i, found in enumerate(sources):
            found.append(scene if state is None else external_source(state, scene, i))
    parts = []
    for i, p in enumerate(placed):
        magnet = np.asarray(p.pose.magnet_position_m, float)
        parts.append(
            synthesize(
                p.probe,
                sources[i],
                np.mod(np.degrees(p.pose.theta0_rad) + steps, 360.0),
                rng,
                f_std_hz,
                amplitude_deg,
                magnet_position_m=magnet,
                reference=scene,
                step=np.arange(len(steps)) % len(stage_deg),
                sweep=np.arange(len(steps)) // len(stage_deg),
                t_s=np.arange(len(steps)) * 10.0,
                **dict(zip(MAGNET, magnet)),
            ).with_columns(**{PROBE: np.full(len(steps), float(i))})
        )
    table = parts[0]
    for part in parts[1:]:
        table = table.concatenate(part)
    return table


# --- the slow path: the time-domain simulator and the estimator ---------------------------------


def simulated_table(
    scenario: Scenario,
    angles_deg: Vector,
    repeats: int,
    rng: np.random.Generator,
    coil_off_skip_s: float = COIL_OFF_SKIP_S,
) -> MeasurementTable:
    """A measurement table from the time-domain simulator and the lever-aware estimator.

    Independent of the lab's physics: :mod:`mows.sim.simulator` integrates the equation of motion in
    the scenario's actual source fields (excitation up to the housing stop, sensor noise), and
    every ring-down is fitted by :func:`mows.estimate.ringdown.fit_ringdown` with the lever's exact
    pickup, as the estimator node does. ``repeats`` full rotation sweeps over ``angles_deg``
    (column ``sweep``; full sweeps rather than repeated ring-downs at each angle, so that a slow
    drift is not confounded with θ0); each sweep is a :class:`mows.sweep.record.SweepRecord` whose
    :meth:`~mows.sweep.record.SweepRecord.table_columns` give the frequencies, damping and fit
    windows; ``amplitude_deg`` is each ring-down's start swing, stop − |θs| at the rest angle θs
    of its sweep's own first-principles decomposition (as the mapper's tables have it), with the
    stop pooled over the whole table. ``t_s`` is the device time of each switch-off (the
    pause between cycles is not simulated), ``temperature_k`` the device's temperature then.
    The reference columns are the scenario's field and gradient at the probe
    (:func:`mows.lab.data.reference.reference_at`). Failed fits are left out and counted in the notes.
    """
    device = SimulatedDevice(scenario, rng)
    sweeps = [_simulated_sweep(device, scenario, angles_deg, coil_off_skip_s) for _ in range(repeats)]
    starts = _start_amplitudes_rad([record for record, _, _ in sweeps], scenario.probe)
    parts = [
        {**record.table_columns(start), "temperature_k": np.array(temperatures), "sweep": np.full(len(start), float(i))}
        for i, ((record, temperatures, _), start) in enumerate(zip(sweeps, starts))
    ]
    columns = {name: np.concatenate([part[name] for part in parts]) for name in parts[0]}
    # The records' t_s count from each sweep's start: the device time of each switch-off instead.
    columns["t_s"] = np.concatenate([[p.t_s for p in record.points] for record, _, _ in sweeps])
    columns["t_s"] = columns["t_s"] - columns["t_s"].min()
    columns.update(reference_columns(scenario, len(columns["f_hz"])))
    failed = sum(count for _, _, count in sweeps)
    notes = (f"{failed} ring-down fits failed and were left out",) if failed else ()
    return MeasurementTable(columns, f"simulated {scenario.name}", notes)


def _simulated_sweep(
    device: SimulatedDevice, scenario: Scenario, angles_deg: Vector, coil_off_skip_s: float
) -> tuple[SweepRecord, list[float], int]:
    """(its SweepRecord, the device's temperature at each switch-off, failed fits) of one
    rotation sweep."""
    record, temperatures, failed = SweepRecord(), [], 0
    for theta0 in np.radians(np.asarray(angles_deg, float)):
        cycle = simulate_cycle(
            device,
            theta0,
            scenario.excitation.amplitude_a,
            excite_s=scenario.excitation.excite_s,
            ringdown_s=scenario.excitation.ringdown_s,
        )
        point = _ringdown_point(scenario, cycle, coil_off_skip_s)
        if point is None:
            failed += 1
            continue
        record.add(point)
        temperatures.append(device.temperature_k)
    return record, temperatures, failed


def _start_amplitudes_rad(records: list[SweepRecord], probe: Probe) -> list[np.ndarray]:
    """Each ring-down's start swing at its fit's first sample, released at the stop about θs
    (:func:`mows.physics.ringdown_average.swing_from_stop_rad`): θs the rest angle at its sweep's own
    first-principles decomposition (0 where that fails), the stop pooled over every ring-down
    of every sweep (:meth:`mows.sweep.record.SweepRecord.stop_amplitude_rad`; the probe's where
    no fit determined θmax). Every ring-down
    starts at the same housing stop, and one sweep's 16 fits pin it only to ~0.3° (two sweeps
    of one 1 mT table pooled 23.34° and 24.16°), which through the amplitude springs is mHz."""
    rests = []
    for record in records:
        decomposition = record.decompose(probe, probe.f00_hz)  # not ok with too few orientations
        rests.append(record.rest_angles_rad(decomposition, probe) if decomposition.ok else np.zeros(len(record.points)))
    every = SweepRecord([point for record in records for point in record.points])
    stop = every.stop_amplitude_rad(np.concatenate(rests), probe.theta_stop_rad) if every.points else np.nan
    return [
        ringdown_average.swing_from_stop_rad(
            stop, rest, [p.damping_per_s for p in record.points], [p.start_offset_s for p in record.points]
        )
        for record, rest in zip(records, rests)
    ]


def _ringdown_point(scenario: Scenario, cycle: CycleRecord, coil_off_skip_s: float) -> SweepPoint | None:
    """The estimator's fit of one simulated ring-down as a :class:`mows.sweep.record.SweepPoint`
    (None when the fit fails)."""
    fit = fit_cycle(cycle, scenario, coil_off_skip_s=coil_off_skip_s)
    if not fit.ok:
        return None
    return SweepPoint.from_fit(
        fit,
        fit.frequency_hz - scenario.probe.f00_hz,
        fit.frequency_std_hz,
        (cycle.block.samples.first_sample_index + cycle.coil_off_index) / cycle.sample_rate_hz,
    )
