"""What several probes in one scene do to each other: the static field of each magnet at the others.

Each probe's magnet is a point dipole of moment m along its lever, at its rest configuration:
deflected by the rest angle θs from its orientation θ0, it points along
cos θs·x' + sin θs·y' and sits at pivot + l·(cos θs·x' + sin θs·y') (:class:`mows.physics.pose.Pose`).
Its field at another magnet, a distance r away, is the exact point-dipole field (Eq. S8 before
its far-field reduction)

    B = μ0/(4π)·[3·r̂(m·r̂) − m]/r³,

with the analytic gradient and Hessian of :class:`mows.physics.sources.PointDipole`. On the
axis of the paper's moment (0.89 mA·m²) at 5 cm that is μ0·2m/(4π·r³) = 1.42 µT, which moves the
neighbour's frequency by about 5 mHz, fifteen times the probe's 0.33 mHz precision
(docs/physics.md §9.10).

So the external field of probe i is the scene's field plus its neighbours' dipoles
(:func:`external_source`), and its frequency is the single-probe first-principles one
(:class:`mows.physics.potential.ArcPotential`) in that field. The rest angles depend on each
other: a neighbour's field across a lever turns it, which turns its moment, which changes the
field it makes at the others. :func:`coupled_rest` solves this by fixed-point iteration; the
fixed point is where every probe's torque vanishes in its neighbours' fields, which is the
minimum of the total energy Σ ½kM·θs² − Σ m_i·B_scene(r_i) − Σ_{i<j} m_i·B_j(r_i) (+ gravity).
The iteration contracts by about m·B_neighbour/(kM·θ) per step: a factor ~1e-4 at
centimetres, so it converges in a few steps.

The coupling here is static: the neighbour's moment at rest, not its swing. A ringing
neighbour adds a field at its own ring-down frequency, which is off the probe's resonance when
the probes' frequencies differ (the way probes sharing a scene are told apart).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from mows.physics.pose import Pose
from mows.physics.potential import DEFAULT_HALF_WIDTH_RAD, ArcPotential
from mows.physics.probe import Probe
from mows.physics.schema import refused
from mows.physics.sources import FieldSource, PointDipole, SumSource

#: The rest angles are converged when no probe's angle changes by more than this in a step.
REST_TOLERANCE_RAD = 1e-13
MAX_ITERATIONS = 50


@dataclasses.dataclass(frozen=True)
class PlacedProbe:
    """One probe of a scene: its constants and where it sits and how it is turned."""

    probe: Probe
    pose: Pose


@dataclasses.dataclass(frozen=True)
class CoupledRest:
    """The self-consistent rest configuration of the probes of a scene (SI units, global frame).

    ``rest_angle_rad[i]`` is probe i's deflection θs from its θ0 at rest; ``moment_am2[i]`` and
    ``position_m[i]`` its magnet's moment and position there; ``iterations`` the fixed-point
    steps it took; ``potentials[i]`` probe i's potential in the scene and its neighbours' field
    of the last step (:func:`coupled_rest`: its neighbours within REST_TOLERANCE_RAD of their rest).
    """

    rest_angle_rad: np.ndarray  # (N,)
    moment_am2: np.ndarray  # (N, 3)
    position_m: np.ndarray  # (N, 3)
    iterations: int
    potentials: tuple[ArcPotential, ...] = ()

    def neighbours(self, index: int) -> SumSource:
        """The dipoles of every magnet but ``index``'s: what probe ``index`` feels of the others."""
        return SumSource(
            PointDipole(self.moment_am2[j], self.position_m[j]) for j in range(len(self.moment_am2)) if j != index
        )

    def neighbour_field_t(self) -> np.ndarray:
        """(N, 3): the neighbours' field at each magnet's rest position, tesla."""
        return np.array([self.neighbours(i).field_t(self.position_m[i]) for i in range(len(self.position_m))])

    def neighbour_gradient_t_per_m(self) -> np.ndarray:
        """(N, 3, 3): the neighbours' gradient G_ij = ∂B_i/∂x_j at each magnet's rest position, T/m."""
        return np.array([self.neighbours(i).gradient_t_per_m(self.position_m[i]) for i in range(len(self.position_m))])


def magnets_at(placed: Sequence[PlacedProbe], rest_angle_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moments (N, 3), A·m², and positions (N, 3), m, of the magnets deflected by ``rest_angle_rad``."""
    moments = np.array([p.probe.moment_am2 * p.pose.moment_direction_at(a) for p, a in zip(placed, rest_angle_rad)])
    positions = np.array([p.pose.magnet_position_at(a, p.probe.lever_m) for p, a in zip(placed, rest_angle_rad)])
    return moments, positions


def check_apart(placed: Sequence[PlacedProbe], names: Sequence[str] = ()) -> None:
    """Refuse magnets closer than twice the sum of their levers: their swings would bring them
    within a few magnet sizes of each other, where a point dipole no longer describes them. The
    one spacing rule of every scene and probe list; ``names`` says where each magnet's place is
    given (a key path: ``probes[1].pose.magnet_position_m``), ``probe k`` if not."""
    names = list(names) or [f"probe {k}" for k in range(len(placed))]
    positions = [np.asarray(p.pose.magnet_position_m, float) for p in placed]
    for i in range(len(placed)):
        for j in range(i + 1, len(placed)):
            distance = float(np.linalg.norm(positions[i] - positions[j]))
            reach = 2.0 * (placed[i].probe.lever_m + placed[j].probe.lever_m)
            if not distance > reach:
                raise refused(
                    names[j],
                    [float(x) for x in positions[j]],
                    f"is {distance * 1e3:.2f} mm from {names[i]} = {[float(x) for x in positions[i]]}: "
                    f"magnets must be more than {reach * 1e3:.2f} mm apart (twice the sum of their levers) "
                    "for point-dipole coupling",
                )


def coupled_rest(
    placed: Sequence[PlacedProbe],
    scene: FieldSource,
    temperature_k: float | None = None,
    half_width_rad: float = DEFAULT_HALF_WIDTH_RAD,
) -> CoupledRest:
    """Where all probes in ``scene`` rest, each in its neighbours' field, to REST_TOLERANCE_RAD
    (module docstring); one probe is a scene of one, in the scene's field alone. Each rests at
    the minimum of its potential it falls into from its θ0 (:meth:`ArcPotential.settled_angle_rad`):
    its rest angle, or beyond spring cancellation its buckled rest off zero. ValueError naming
    the probe if one comes to rest nowhere within ±``half_width_rad`` or the iteration does not
    converge, and for magnets too close to pass each other."""
    if len(placed) == 0:
        raise ValueError("a scene needs at least one probe")
    check_apart(placed)
    angles = np.zeros(len(placed))
    for iteration in range(1, MAX_ITERATIONS + 1):
        state = CoupledRest(angles, *magnets_at(placed, angles), iteration)
        potentials = tuple(
            _potential(p, scene + state.neighbours(i), temperature_k, half_width_rad) for i, p in enumerate(placed)
        )
        updated = np.array([float(p.settled_angle_rad()) for p in potentials])
        unstable = np.flatnonzero(~np.isfinite(updated))
        if unstable.size:
            raise ValueError(
                f"probe {int(unstable[0])} comes to rest nowhere within ±{half_width_rad:g} rad in the scene "
                "and its neighbours' field (it falls onto its stop)"
            )
        # What probe i feels changes only by its neighbours' steps: converged when none moves.
        moved = np.abs(updated - angles)
        step = max(float(np.max(np.delete(moved, i), initial=0.0)) for i in range(len(placed)))
        angles = updated
        if step <= REST_TOLERANCE_RAD:
            return CoupledRest(angles, *magnets_at(placed, angles), iteration, potentials)
    raise ValueError(f"the probes' rest angles did not converge in {MAX_ITERATIONS} steps (last change {step:.3g} rad)")


def external_source(state: CoupledRest, scene: FieldSource, index: int) -> FieldSource:
    """The field probe ``index`` sits in: the scene's plus its neighbours' dipoles at rest."""
    return scene + state.neighbours(index)


def _potential(
    placed: PlacedProbe,
    source: FieldSource,
    temperature_k: float | None,
    half_width_rad: float = DEFAULT_HALF_WIDTH_RAD,
) -> ArcPotential:
    return ArcPotential.from_source(placed.probe, source, placed.pose, temperature_k, half_width_rad=half_width_rad)


def coupled_frequencies_hz(
    placed: Sequence[PlacedProbe],
    scene: FieldSource,
    amplitude_rad: float = 0.0,
    temperature_k: float | None = None,
) -> np.ndarray:
    """(N,): each probe's ring-down frequency at swing ``amplitude_rad`` in the scene and its
    neighbours' fields at the coupled rest (Eq. S1 with the exact stiffness), Hz."""
    state = coupled_rest(placed, scene, temperature_k)
    return np.array([float(p.frequency_hz(amplitude_rad)) for p in state.potentials])
