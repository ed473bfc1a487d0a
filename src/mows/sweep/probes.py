"""A rotation sweep of one or several probes decomposed: each probe's external in-plane field and
gradient, its neighbours' fields in the model when it has neighbours.

Each probe's share of the sweep (:class:`ProbeSweep`) is its record of successful ring-downs,
each with the sweep's step (the stage's turn, one excitation of every group) it was taken at.
:func:`decompose_probes` decomposes every share alone
(:meth:`mows.sweep.record.SweepRecord.decompose`); one probe is then done. With several, probe k
feels the external field and gradient at its magnet and its neighbours' dipole fields
(:mod:`mows.physics.coupling`):

    B_k(r) = B_ext,k + G_ext,k·(r − r_k) + Σ_{l≠k} B_dipole(m_l(θ0_l, θs_l), r_l(θ0_l, θs_l); r),

and each neighbour's moment turns with its orientation θ0_l at that step and its rest angle
θs_l, which its own external field and its neighbours set. So the neighbours' terms change from
point to point; they are known once the external fields are, and they are about 1.4 µT at 5 cm
for the paper's moment, far above a sweep's precision: a decomposition that leaves them out
reports them as part of the external field, biased (tests/sweep/test_multiprobe_sweep.py). For
``passes`` rounds the neighbours' fields are held at those the present estimates give and each
probe is decomposed again with them as known terms of the first-principles model
(:class:`mows.sweep.shift_model.NeighbourFields`: exact dipole field, gradient and Hessian at the
magnet, so the field along the whole arc). They depend on the estimates only through the rest
angles (a few degrees move them by a few percent), so the rounds converge at once: once a round
would move every probe's neighbour fields by less than :data:`SETTLED_STD` of its own σ, it is
not run (after the first coupled round they move by ~0.002σ); the rest angles at each step are
the coupled ones, iterated to a fixed point.

How each share is decomposed (:class:`DecomposeOptions`) depends on how the sweep was made. Probes
rung together by the multi-tone drive do not start from the housing stop: each ring-down starts
with the swing its joint fit measured. Spread over a coil pair's field, they sit where its
curvature is not small, and left in the residual the in-plane 3θ0 curvature leaks into the field
wherever the points' σ differ, so it is fitted where the orientations allow it (7 distinct ones;
its 1θ0 part cannot be told from the field). A lone probe's ring-downs start from the stop.

The probes sit at their magnets' positions in the stage's rotation-plane frame, in parallel
planes (the decomposition is in-plane), each turned about its own magnet. Each ring-down's θ0 is
the probe's own, as its fit says (the stage's angle plus the probe's home orientation). Where
probe k rang, a neighbour's moment is turned to that neighbour's θ0 at the same step
(:func:`step_orientations_rad`): from its own fits of that step, else the stage's angle there
plus its home orientation. The published model has no neighbour terms, a probe without a
decomposition leaves its neighbours' fields unknown, and magnets closer than :data:`MIN_APART_M`
are no point dipoles to each other: the probes are then decomposed alone, each message saying so
(:data:`UNCOUPLED_NOTE`).
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import functools
import itertools
from collections.abc import Callable, Iterable, Sequence
from typing import TypeVar

import numpy as np

from mows.estimate.probe_set import ProbeEntry
from mows.estimate.ringdown import FitOptions, swing_from_signal_rad
from mows.estimate.ringdown.types import RingdownFit
from mows.physics.coupling import PlacedProbe
from mows.physics.fluxgate import FluxgatePair, pickup_scale_t
from mows.physics.pose import Pose
from mows.physics.sources import PointDipole
from mows.sweep.decompose import orientations_problem
from mows.sweep.decomposition import Decomposition, DecompositionStatus
from mows.sweep.record import SweepPoint, SweepRecord
from mows.sweep.shift_model import NeighbourFields, Ringdowns, local_potential

T = TypeVar("T")
REST_ITERATIONS = 4  # the rest angles' fixed point contracts by ~1e-4 a step at centimetres
DEFAULT_PASSES = 2
SETTLED_STD = 0.01  # a round whose known terms move by less than this many σ of the estimate is not run
UNCOUPLED_NOTE = "decomposed without its neighbours' fields"
# Closer magnets are no point dipoles to each other: each swings on a lever of ~2 mm and is
# ~2 mm across, and a neighbour's field there varies over both.
MIN_APART_M = 0.01


@dataclasses.dataclass(frozen=True)
class DecomposeOptions:
    """How each probe's record is decomposed (module docstring): the ``model``, f00 fitted
    (``f00_free``) or calibrated, the 3θ0 ``curvature`` fitted where the orientations allow it
    (first-principles model), and the ring-downs' start swings as their fits measured them
    (``measured_swings``, a multi-tone excitation's) or from the housing stop, pooled."""

    model: str = "first_principles"
    f00_free: bool = False
    curvature: bool = True
    measured_swings: bool = True


@dataclasses.dataclass(frozen=True)
class ProbeSweep:
    """One probe's share of a sweep: its id, the probe placed (constants, magnet position), its
    successful ring-downs, the f00 its shifts count from, and the sweep's step of each point."""

    probe_id: int
    placed: PlacedProbe
    record: SweepRecord
    f00_hz: float
    steps: np.ndarray

    @classmethod
    def of_entry(cls, entry: ProbeEntry, record: SweepRecord, steps: Sequence[int]) -> ProbeSweep:
        """A listed probe's share: at its ``position_m``, its moment along the plane's e1 at
        θ0 = 0; f00 as its ring-downs carry it (:func:`f00_of`), the entry's without any."""
        placed = PlacedProbe(entry.probe, Pose(magnet_position_m=entry.position_m))
        f00_hz = f00_of(record) if record.points else entry.f00_hz
        return cls(entry.probe_id, placed, record, f00_hz, np.asarray(steps, int))

    @property
    def theta0_rad(self) -> np.ndarray:
        return np.array([p.theta0_rad for p in self.record.points], float)

    @functools.cached_property
    def _measured(self) -> Ringdowns | None:
        """The record's :meth:`~mows.sweep.record.SweepRecord.measured_ringdowns`, once: their
        swings about each rest angle are tabulated on first use, for every pass of
        :func:`decompose_probes` (the record does not change while it is decomposed)."""
        return self.record.measured_ringdowns()

    def decompose(
        self, options: DecomposeOptions, neighbours: NeighbourFields | None = None, start=None
    ) -> Decomposition:
        """Its record decomposed, with the ``neighbours``' fields at its ring-downs when given,
        from the parameters ``start`` when given (:func:`mows.sweep.decompose.decompose`'s)."""
        record, model = self.record, options.model
        if not record.points:
            why = f"no successful ring-down of probe {self.probe_id} ({record.failed} failed)"
            return Decomposition(model, DecompositionStatus.NO_DECOMPOSITION, why, f00_free=options.f00_free)
        curvature = (
            options.curvature
            and model == "first_principles"
            and not orientations_problem(self.theta0_rad, options.f00_free, curvature=True)
        )
        return record.decompose(
            self.placed.probe,
            self.f00_hz,
            model,
            options.f00_free,
            neighbours,
            curvature=curvature,
            measured=self._measured if options.measured_swings else None,
            start=start,
        )


def f00_of(record: SweepRecord) -> float:
    """The estimator's f00 of a record's probe, as each OK ring-down carries it (frequency − shift)."""
    return float(np.mean([p.frequency_hz - p.shift_hz for p in record.points]))


def sweeps_of(
    placed: Sequence[PlacedProbe],
    points: Sequence[Sequence[RingdownFit]],
    pair: FluxgatePair,
    channels: str = FitOptions.channels,
) -> list[ProbeSweep]:
    """Each probe's share from the joint fits of every point (one fit per probe, by ``probe_id``
    = the index in ``placed``), shifts against each probe's f00, each ring-down's start swing
    from its signal's size through the absolute pickup of the fits' channel combination
    ``channels`` of the fluxgate ``pair`` (:func:`mows.estimate.ringdown.summary.swing_from_signal_rad`).
    Points where a probe's fit is not OK are left out of every probe's share."""
    usable = [fits for fits in points if all(f.ok for f in fits) and len(fits) == len(placed)]
    sweeps = []
    for k, p in enumerate(placed):
        f00_hz = p.probe.f00_hz
        scale_t = pickup_scale_t(pair, p.pose.magnet_position_m, p.probe.moment_am2, channels)
        record = SweepRecord()
        for point in usable:
            fit = next(f for f in point if f.probe_id == k)
            shifted = SweepPoint.from_fit(fit, fit.frequency_hz - f00_hz, fit.frequency_std_hz)
            record.add(dataclasses.replace(shifted, amplitude_rad=swing_from_signal_rad(fit, scale_t)))
        sweeps.append(ProbeSweep(k, p, record, f00_hz, np.arange(len(usable))))
    return sweeps


def decompose_probes(
    sweeps: Sequence[ProbeSweep],
    options: DecomposeOptions = DecomposeOptions(),
    coupling: bool = True,
    passes: int = DEFAULT_PASSES,
    orientations_rad: np.ndarray | None = None,
) -> list[Decomposition]:
    """Each probe's decomposition, in the order of ``sweeps`` (module docstring): with
    neighbours, their fields in the model unless ``coupling`` is False or they cannot be.
    ``orientations_rad`` (probes, steps): every probe's θ0 at every step of the sweep, which
    sets its moment where its neighbours ring (:func:`step_orientations_rad`); by default each
    probe's own θ0 at each step (:func:`own_orientations_rad`)."""
    results = _concurrently(lambda s: s.decompose(options), sweeps)
    if len(sweeps) == 1 or not coupling:
        return results
    why = crowding(sweeps)
    if why or options.model != "first_principles":
        return [uncoupled(d, why) for d in results]
    if not all(r.ok for r in results):  # a probe without a decomposition leaves its field unknown
        return [uncoupled(r) for r in results]
    orientations = own_orientations_rad(sweeps) if orientations_rad is None else orientations_rad
    used: list[NeighbourFields] = []
    for done in range(passes):
        fields = neighbour_fields(sweeps, [r.parameters for r in results], orientations)
        if used and all(map(settled, used, fields, results)):
            break
        used = fields
        # Each pass starts where the last ended: the neighbours' fields move the optimum by
        # microtesla, a few steps of the fit, not the whole way from the harmonics.
        coupled = _concurrently(
            lambda job: job[0].decompose(options, job[1], job[2].parameters), zip(sweeps, fields, results)
        )
        if not all(r.ok for r in coupled):
            return results if done else [uncoupled(r) for r in results]
        results = coupled
    return results


def _concurrently(decompose: Callable[[T], Decomposition], jobs: Iterable[T]) -> list[Decomposition]:
    """``decompose`` of each job, in their order, one thread each: the probes' fits are
    independent and NumPy runs their array work outside the GIL, so on a busy computer they
    share the cores the process gets instead of waiting for each other (a three-probe sweep's
    decomposition took 3.9–5.3 s instead of 7.5 s of wall time at load 13 on 2 cores, the same
    CPU time and the same numbers)."""
    jobs = list(jobs)
    if len(jobs) == 1:
        return [decompose(jobs[0])]
    with concurrent.futures.ThreadPoolExecutor(len(jobs)) as pool:
        return list(pool.map(decompose, jobs))


def settled(before: NeighbourFields, after: NeighbourFields, decomposition: Decomposition) -> bool:
    """Whether the neighbours' field and gradient at a probe moved by less than :data:`SETTLED_STD`
    of its decomposition's σ (in-plane field, gradient), at every point: another round with
    them would move its estimate by less."""
    field_std = np.sqrt(np.diag(decomposition.field_covariance_t2)).min()
    gradient_std = np.sqrt(np.diag(decomposition.gradient_covariance)).min()
    moved_field = np.abs(after.field_t - before.field_t).max(initial=0.0)
    moved_gradient = np.abs(after.gradient_t_per_m - before.gradient_t_per_m).max(initial=0.0)
    return bool(moved_field < SETTLED_STD * field_std and moved_gradient < SETTLED_STD * gradient_std)


def report(sweeps: Sequence[ProbeSweep], decompositions: Sequence[Decomposition]) -> str:
    """Each decomposition's report, with its notes when it succeeded; by probe with several."""
    texts = [f"{d.report()} ({d.message})" if d.ok and d.message else d.report() for d in decompositions]
    if len(sweeps) == 1:
        return texts[0]
    return "; ".join(f"probe {s.probe_id}: {text}" for s, text in zip(sweeps, texts))


def problems(sweeps: Sequence[ProbeSweep], decompositions: Sequence[Decomposition]) -> str:
    """Why probes were not decomposed ('' when all were); by probe with several."""
    failed = [(s, d.message) for s, d in zip(sweeps, decompositions) if not d.ok]
    if len(sweeps) == 1:
        return "".join(message for _, message in failed)
    return "; ".join(f"probe {s.probe_id}: {message}" for s, message in failed)


def crowding(sweeps: Sequence[ProbeSweep]) -> str:
    """Why the probes cannot be point dipoles in each other's model, '' when they can: two
    magnets closer than :data:`MIN_APART_M` (e.g. a ``probes`` list without places)."""
    for a, b in itertools.combinations(sweeps, 2):
        apart_m = float(np.linalg.norm(np.subtract(a.placed.pose.magnet_position_m, b.placed.pose.magnet_position_m)))
        if apart_m < MIN_APART_M:
            return f"probes {a.probe_id} and {b.probe_id} are listed {apart_m * 1e3:.1f} mm apart (position_m)"
    return ""


def uncoupled(decomposition: Decomposition, why: str = "") -> Decomposition:
    """``decomposition`` with its message saying the neighbours' fields are left in its field
    (and ``why``, when given)."""
    if not decomposition.ok:
        return decomposition
    note = f"{UNCOUPLED_NOTE}: {why}" if why else UNCOUPLED_NOTE
    message = f"{decomposition.message}; {note}" if decomposition.message else note
    return dataclasses.replace(decomposition, message=message)


def step_orientations_rad(sweeps: Sequence[ProbeSweep], stage_rad) -> np.ndarray:
    """(probes, steps): each probe's θ0 at each step of the sweep, the stage at ``stage_rad``,
    from its own fits of that step; where it has none, the stage's angle there plus its home
    orientation (the circular mean of its fits' θ0 less the stage's angle at theirs). NaN for a
    probe with no fit at all (it has no decomposition, so the coupling is not put in the model)."""
    stage = np.asarray(stage_rad, float)
    table = np.full((len(sweeps), len(stage)), np.nan)
    for row, s in zip(table, sweeps):
        theta0 = s.theta0_rad
        if not theta0.size:
            continue
        home = float(np.angle(np.mean(np.exp(1j * (theta0 - stage[s.steps])))))
        row[:] = stage + home
        row[s.steps] = theta0
    return table


def own_orientations_rad(sweeps: Sequence[ProbeSweep]) -> np.ndarray:
    """(probes, steps): each probe's θ0 at each step, from its own points, for sweeps whose every
    probe has a point at every step. ValueError otherwise."""
    counts = {len(s.theta0_rad) for s in sweeps}
    if len(counts) != 1 or any(not np.array_equal(s.steps, np.arange(len(s.theta0_rad))) for s in sweeps):
        raise ValueError(f"every probe of a sweep needs one measurement per point; got {sorted(counts)} points")
    return np.array([s.theta0_rad for s in sweeps], float)


def neighbour_fields(
    sweeps: Sequence[ProbeSweep], parameters: Sequence[np.ndarray], orientations_rad: np.ndarray | None = None
) -> list[NeighbourFields]:
    """For each probe, its neighbours' dipole fields at its magnet at each of its points, with
    each probe's external field and gradient ``parameters`` (Bx, By, Gs, Gd, Gxy, …) setting
    the rest angles and every probe at its ``orientations_rad`` (probes, steps; default: each
    one's own θ0 at each step) of the step the point was taken at."""
    orientations = own_orientations_rad(sweeps) if orientations_rad is None else np.asarray(orientations_rad, float)
    count, steps = orientations.shape
    where = np.array([s.placed.pose.magnet_position_m for s in sweeps], float)
    fields = [NeighbourFields(np.zeros((steps, 3)), np.zeros((steps, 3, 3)), np.zeros((steps, 3, 3, 3)))] * count
    for _ in range(REST_ITERATIONS):
        rest = np.array(
            [
                local_potential(p, theta0, s.placed.probe, f).rest_angle_rad()
                for s, p, theta0, f in zip(sweeps, parameters, orientations, fields)
            ]
        )
        fields = _dipole_fields(sweeps, orientations, rest, where)
    return [
        NeighbourFields(f.field_t[s.steps], f.gradient_t_per_m[s.steps], f.hessian_t_per_m2[s.steps])
        for s, f in zip(sweeps, fields)
    ]


def _dipole_fields(
    sweeps: Sequence[ProbeSweep], orientations_rad: np.ndarray, rest: np.ndarray, where: np.ndarray
) -> list[NeighbourFields]:
    """The neighbours' field, gradient and Hessian at each magnet at each step, every probe at
    its orientation and ``rest`` angle of that step."""
    count, points = rest.shape
    moments = np.empty((count, points, 3))
    positions = np.empty((count, points, 3))
    for k, s in enumerate(sweeps):
        for j, theta0 in enumerate(orientations_rad[k]):
            pose = s.placed.pose.with_theta0(float(theta0))
            moments[k, j] = s.placed.probe.moment_am2 * pose.moment_direction_at(rest[k, j])
            positions[k, j] = pose.magnet_position_at(rest[k, j], s.placed.probe.lever_m)
    fields = []
    for k in range(count):
        field, gradient, hessian = np.zeros((points, 3)), np.zeros((points, 3, 3)), np.zeros((points, 3, 3, 3))
        for other in range(count):
            if other == k:
                continue
            for j in range(points):
                dipole = PointDipole(moments[other, j], positions[other, j])
                field[j] += dipole.field_t(where[k])
                gradient[j] += dipole.gradient_t_per_m(where[k])
                hessian[j] += dipole.hessian_t_per_m2(where[k])
        fields.append(NeighbourFields(field, gradient, hessian))
    return fields
