"""Each probe's external field and gradient from a sweep of several probes, the coupling in the model.

In a sweep of several probes every point turns them all (their stages) and measures each one's
frequency shift (:func:`mows.estimate.segments.fit_joint_segment`). Probe k feels the external field and
gradient at its magnet and its neighbours' dipole fields (:mod:`mows.physics.coupling`):

    B_k(r) = B_ext,k + G_ext,k·(r − r_k) + Σ_{l≠k} B_dipole(m_l(θ0_l, θs_l), r_l(θ0_l, θs_l); r),

and each neighbour's moment turns with its orientation θ0_l at that point and its rest angle
θs_l, which its own external field and its neighbours set. So the neighbours' terms change from
point to point; they are known once the external fields are, and they are about 1.4 µT at 5 cm
for the paper's moment, far above a sweep's precision: a decomposition that leaves them out
reports them as part of the external field, biased (tests/sweep/test_multiprobe_sweep.py).

:func:`decompose_probes` first decomposes each probe alone, then, for ``passes`` rounds, holds
the neighbours' fields at those the present estimates give and decomposes each probe again
with them as known terms of the first-principles model
(:class:`mows.sweep.decompose.NeighbourFields`: exact dipole field, gradient and Hessian at the
magnet, so the field along the whole arc). The neighbours' fields depend on the estimates only
through their rest angles (a few degrees move them by a few percent), so the rounds converge
at once; the rest angles at each point are the coupled ones, iterated to a fixed point.

Each probe's decomposition also fits the external field's in-plane 3θ0 curvature over its
lever's arc when the sweep has the 7 orientations it needs
(:func:`mows.sweep.decompose.decompose`, ``curvature``). Several probes spread over a coil
pair's field sit where its curvature is not small, and left in the residual it leaks into the
field wherever the points' σ differ. The curvature's 1θ0 part cannot be told from the field.

The loop takes any probe's share of a sweep that can decompose itself (:class:`SweepOfProbe`):
the bench's :class:`ProbeSweep`, a point per step, and the mapper's records
(:class:`mows.sweep.probes.RecordSweep`), whose points are the probe's successful ring-downs,
each at the step it was taken at. Where probe k rang, each neighbour's moment is turned to the
neighbour's own θ0 at that step (``orientations_rad``: every probe's θ0 at every step), not
to probe k's.

The probes rotate in the global x–y plane (the decomposition's frame).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from mows.estimate.ringdown import FitOptions, start_swing_rad
from mows.estimate.ringdown.types import RingdownFit
from mows.physics.coupling import PlacedProbe
from mows.physics.fluxgate import FluxgatePair, pickup_scale_t
from mows.physics.sources import PointDipole
from mows.sweep.decompose import (
    Decomposition,
    NeighbourFields,
    Ringdowns,
    decompose,
    local_potential,
    orientations_problem,
)

REST_ITERATIONS = 4  # the rest angles' fixed point contracts by ~1e-4 a step at centimetres
DEFAULT_PASSES = 2
UNCOUPLED_NOTE = "decomposed without its neighbours' fields"


class SweepOfProbe(Protocol):
    """What the coupled decomposition needs of one probe's share of a sweep: the probe (its
    constants and its magnet's position), its θ0 at each of its ring-downs, the sweep's step
    (the stage's turn, one excitation of every group) each was taken at, and its decomposition
    with the neighbours' fields at its ring-downs (None: alone)."""

    @property
    def placed(self) -> PlacedProbe: ...

    @property
    def theta0_rad(self) -> np.ndarray: ...

    @property
    def steps(self) -> np.ndarray: ...

    def decompose(self, neighbours: NeighbourFields | None) -> Decomposition: ...


@dataclasses.dataclass(frozen=True)
class ProbeSweep:
    """One probe's share of a sweep of several: the probe (constants, its magnet's position),
    its calibrated f00, and per point its θ0, measured shift f − f00 and σ, and how its ring-down
    was recorded (:class:`mows.sweep.decompose.Ringdowns`, or None: small amplitude). Point j
    is the sweep's step j."""

    placed: PlacedProbe
    f00_hz: float
    theta0_rad: np.ndarray
    shift_hz: np.ndarray
    shift_std_hz: np.ndarray
    ringdowns: Ringdowns | None = None

    @property
    def steps(self) -> np.ndarray:
        return np.arange(len(self.theta0_rad))

    def decompose(self, neighbours: NeighbourFields | None) -> Decomposition:
        """Its decomposition by :func:`mows.sweep.decompose.decompose`, the 3θ0 curvature fitted
        when its orientations allow it."""
        return decompose(
            self.theta0_rad,
            self.shift_hz,
            self.shift_std_hz,
            self.placed.probe,
            self.f00_hz,
            ringdowns=self.ringdowns,
            neighbours=neighbours,
            curvature=not orientations_problem(self.theta0_rad, curvature=True),
        )


def sweeps_of(
    placed: Sequence[PlacedProbe],
    points: Sequence[Sequence[RingdownFit]],
    pair: FluxgatePair,
    channels: str = FitOptions.channels,
) -> list[ProbeSweep]:
    """Each probe's :class:`ProbeSweep` from the fits of every point (one fit per probe, by
    ``probe_id`` = the index in ``placed``; the fits' channel combination ``channels`` of the
    fluxgate ``pair``), shifts against each probe's f00. Points where a
    probe's fit is not OK are left out of every probe's sweep (the neighbours' orientations at
    a point are part of each probe's model, so the points stay common)."""
    usable = [fits for fits in points if all(f.ok for f in fits) and len(fits) == len(placed)]
    sweeps = []
    for k, p in enumerate(placed):
        fits = [next(f for f in point if f.probe_id == k) for point in usable]
        scale_t = pickup_scale_t(pair, p.pose.magnet_position_m, p.probe.moment_am2, channels)
        ringdowns = Ringdowns(
            math.nan,
            np.array([f.damping_per_s for f in fits]),
            np.array([f.duration_s for f in fits]),
            np.array([f.pickup for f in fits]),
            np.array([start_swing_rad(f, scale_t) for f in fits]),
        )
        sweeps.append(
            ProbeSweep(
                p,
                p.probe.f00_hz,
                np.array([f.theta0_rad for f in fits]),
                np.array([f.frequency_hz - p.probe.f00_hz for f in fits]),
                np.array([f.frequency_std_hz for f in fits]),
                ringdowns,
            )
        )
    return sweeps


def decompose_probes(
    sweeps: Sequence[SweepOfProbe],
    coupling: bool = True,
    passes: int = DEFAULT_PASSES,
    orientations_rad: np.ndarray | None = None,
) -> list[Decomposition]:
    """Each probe's external in-plane field and gradient (module docstring); with ``coupling``
    False each probe is decomposed alone, as if it had no neighbours. ``orientations_rad``
    (probes, steps): every probe's θ0 at every step of the sweep, which sets its moment where
    its neighbours ring; by default each probe's own θ0 at each step (:func:`own_orientations_rad`).
    When the coupling cannot be put in the model (a probe without a decomposition leaves its
    field unknown), each probe is returned alone, its message saying so (:data:`UNCOUPLED_NOTE`)."""
    results = [s.decompose(None) for s in sweeps]
    if not coupling or len(sweeps) == 1:
        return results
    orientations = own_orientations_rad(sweeps) if orientations_rad is None else orientations_rad
    for done in range(passes):
        fields = (
            None
            if not all(r.ok for r in results)
            else neighbour_fields(sweeps, [r.parameters for r in results], orientations)
        )
        coupled = None if fields is None else [s.decompose(f) for s, f in zip(sweeps, fields)]
        if coupled is None or not all(r.ok for r in coupled):
            return results if done else [uncoupled(r) for r in results]
        results = coupled
    return results


def own_orientations_rad(sweeps: Sequence[SweepOfProbe]) -> np.ndarray:
    """(probes, steps): each probe's θ0 at each step, from its own points, for sweeps whose every
    probe has a point at every step. ValueError otherwise."""
    counts = {len(s.theta0_rad) for s in sweeps}
    if len(counts) != 1 or any(not np.array_equal(s.steps, np.arange(len(s.theta0_rad))) for s in sweeps):
        raise ValueError(f"every probe of a sweep needs one measurement per point; got {sorted(counts)} points")
    return np.array([s.theta0_rad for s in sweeps], float)


def uncoupled(decomposition: Decomposition, why: str = "") -> Decomposition:
    """``decomposition`` with its message saying the neighbours' fields are left in its field
    (and ``why``, when given)."""
    if not decomposition.ok:
        return decomposition
    note = f"{UNCOUPLED_NOTE}: {why}" if why else UNCOUPLED_NOTE
    message = f"{decomposition.message}; {note}" if decomposition.message else note
    return dataclasses.replace(decomposition, message=message)


def neighbour_fields(
    sweeps: Sequence[SweepOfProbe], parameters: Sequence[np.ndarray], orientations_rad: np.ndarray | None = None
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
    sweeps: Sequence[SweepOfProbe], orientations_rad: np.ndarray, rest: np.ndarray, where: np.ndarray
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
