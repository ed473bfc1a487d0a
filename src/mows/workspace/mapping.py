"""A workspace map as the mapper makes it, live beside an arm or from a recording: the poses it
asks the arm for, the checks each reported pose must pass, and the model fitted to the sweeps.

:class:`PosePlan` proposes each next pose: among candidates on the workspace's bounding sphere
(where a harmonic field is fixed, :func:`mows.workspace.design.boundary_positions`), each with
its own orientation, those within the arm's reach, the one whose sweep adds the most
information (D-optimal, :mod:`mows.workspace.design`) given the sweeps at the poses the arm
reported. :class:`PoseWatch` follows ``measured_cp`` through a sweep: the arm has arrived when
its report is at the goal and still; a sweep whose probe moved, or whose last report is older
than a sweep allows, is refused with the reason. :func:`workspace_map` fits every sweep at its
reported pose, the arm's stated accuracy carried (:mod:`mows.workspace.poses`) in the fit and
in the cross-validation over sweeps that chooses its degree: the one function of the mapper node and ``mows map``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from mows.physics.probe import Probe
from mows.sweep.decomposition import Decomposition
from mows.workspace.arm import NS_PER_S, Reach, StampedPose, matrix_quaternion, pose_problem
from mows.workspace.design import boundary_positions, candidate_designs, information, next_best, random_rotation
from mows.workspace.fit import DegreeChoice, WorkspaceModel
from mows.workspace.harmonics import SolidHarmonics, coefficient_count
from mows.workspace.observations import Observation, gravity_field_t, plane_readout, sweep_observation
from mows.workspace.poses import PoseError, map_with_pose_error, rotation

# What a sweep is expected to give before the first is in (σ of Bx, By in T, of the gradient's
# three in T/m): ten orientations of one ring-down each at the paper's frequency noise.
FIRST_SWEEP_STD = (0.1e-6, 0.1e-6, 30e-6, 30e-6, 30e-6)
DEGREES = (2, 3, 4, 5, 6, 7, 8)
DESIGN_DEGREE = 4  # the degree the next pose is chosen for: the map's first dozen sweeps hold it
CANDIDATES = 240
HELD_OUT_POINTS = 400  # points in the ball the map's rms σ is reported over


@dataclasses.dataclass(frozen=True)
class MapSettings:
    """A workspace ball (``centre_m``, ``radius_m``, in the arm's base frame ``frame_id``), the
    arm's ``reach`` and stated ``accuracy``, gravity in that frame, and the degrees tried."""

    centre_m: tuple[float, ...]
    radius_m: float
    accuracy: PoseError
    reach: Reach = Reach()
    frame_id: str = "arm_base"
    gravity_m_per_s2: tuple[float, float, float] = (0.0, 0.0, -9.80665)
    degrees: tuple[int, ...] = DEGREES
    seed: int = 0

    def __post_init__(self) -> None:
        centre = np.asarray(self.centre_m, float)
        if centre.shape != (3,) or not np.all(np.isfinite(centre)):
            raise ValueError(f"a workspace's centre is a finite 3-vector in metres, got {self.centre_m!r}")
        if not (math.isfinite(self.radius_m) and self.radius_m > 0):
            raise ValueError(f"a workspace's radius is a positive length in metres, got {self.radius_m!r}")


class PosePlan:
    """The next pose to sweep at (module docstring), for a probe of ``probe``'s lever."""

    def __init__(self, settings: MapSettings, probe: Probe):
        self.settings = settings
        rng = np.random.default_rng(settings.seed)
        positions = boundary_positions(CANDIDATES, settings.radius_m, settings.centre_m)
        rotations = [random_rotation(rng) for _ in positions]
        reachable = [k for k, p in enumerate(positions) if not settings.reach.problem(p)]
        self._poses = [(positions[k], rotations[k]) for k in reachable]
        self._weight = gravity_field_t(probe, settings.gravity_m_per_s2)
        self._lever_m = probe.lever_m
        self._basis = SolidHarmonics(DESIGN_DEGREE, tuple(settings.centre_m), settings.radius_m)
        self._designs = candidate_designs(
            self._basis, [(p, plane_readout(r[:, :2].T, self._lever_m, self._weight)) for p, r in self._poses]
        )
        self._left = list(range(len(self._poses)))
        self._info = information(self._basis, [])
        self._expected = np.diag(np.square(FIRST_SWEEP_STD))
        self._goal: int | None = None

    def next_goal(self) -> StampedPose:
        """The next pose to ask the arm for (stamp 0); ValueError when no candidate is left."""
        if not self._left:
            raise ValueError(
                f"no pose left within the arm's reach on the workspace's sphere "
                f"({len(self._poses)} of {CANDIDATES} candidates were within it)"
            )
        choice = next_best(self._basis, self._info, [self._designs[k] for k in self._left], self._expected)
        self._goal = self._left.pop(choice)
        position, turn = self._poses[self._goal]
        return StampedPose(0, self.settings.frame_id, position, matrix_quaternion(turn))

    def swept(self, observation: Observation) -> None:
        """A sweep at the goal is in: its information at the pose the arm reported."""
        design = candidate_designs(self._basis, [(observation.position_m, observation.readout)])[0]
        self._info = self._info + design.T @ np.linalg.solve(observation.covariance, design)
        self._expected = observation.covariance


def rotation_angle_rad(a: np.ndarray, b: np.ndarray) -> float:
    """The angle of the rotation that takes ``a`` to ``b``."""
    return float(np.arccos(np.clip((np.trace(a.T @ b) - 1.0) / 2.0, -1.0, 1.0)))


def pose_distance(a: StampedPose, b: StampedPose) -> tuple[float, float]:
    """How far apart two poses are: metres, radians."""
    return float(np.linalg.norm(a.position_m - b.position_m)), rotation_angle_rad(a.rotation, b.rotation)


def turned(pose: StampedPose, theta0_rad: float) -> StampedPose:
    """``pose`` turned by ``theta0_rad`` about its own z, the normal of the probe's plane: where
    an arm whose last joint turns the probe puts it for the orientation θ0."""
    return dataclasses.replace(
        pose, orientation_xyzw=matrix_quaternion(pose.rotation @ rotation(np.array([0.0, 0.0, theta0_rad])))
    )


class PoseWatch:
    """``measured_cp`` through a move and a sweep. The arm is still when two successive reports
    are within ``tolerance_m`` and ``tolerance_rad`` of each other, and at a goal when its
    report is that near the goal; a sweep's reports must stay that near its first, the
    sweep's pose (``start``). With ``turns_probe`` the arm turns the probe about the plane's
    normal through the sweep: then only the position and the normal must stay."""

    def __init__(self, tolerance_m: float, tolerance_rad: float, max_age_s: float, reach: Reach, turns_probe=False):
        self.tolerance_m, self.tolerance_rad, self.max_age_s, self.reach = tolerance_m, tolerance_rad, max_age_s, reach
        self.turns_probe = turns_probe
        self.latest: StampedPose | None = None
        self._previous: StampedPose | None = None
        self.start: StampedPose | None = None
        self._moved = (0.0, 0.0)

    def on_pose(self, pose: StampedPose) -> None:
        self._previous, self.latest = self.latest, pose
        if self.start is not None and pose.frame_id == self.start.frame_id:
            distance_m, angle_rad = pose_distance(pose, self.start)
            if self.turns_probe:  # the plane's normal, the turn's axis, must stay
                normals = float(np.dot(pose.rotation[:, 2], self.start.rotation[:, 2]))
                angle_rad = float(np.arccos(np.clip(normals, -1.0, 1.0)))
            self._moved = (max(self._moved[0], distance_m), max(self._moved[1], angle_rad))

    def _near(self, a: StampedPose | None, b: StampedPose | None) -> bool:
        if a is None or b is None or a.frame_id != b.frame_id:
            return False
        distance_m, angle_rad = pose_distance(a, b)
        return distance_m <= self.tolerance_m and angle_rad <= self.tolerance_rad

    def still(self) -> bool:
        return self._near(self.latest, self._previous)

    def arrived(self, goal: StampedPose) -> bool:
        """The arm reports the goal, and has stopped there."""
        return self._near(self.latest, goal) and self.still()

    def start_problem(self, now_ns: int, frame_id: str) -> str:
        """Why the latest report cannot stand for a sweep starting at ``now_ns`` ('' when it
        can; the sweep's watch starts from it)."""
        if self.latest is None:
            return "no pose from the arm's measured_cp"
        if self.latest.frame_id != frame_id:
            return f"the arm reports poses in frame {self.latest.frame_id!r}, the map is in {frame_id!r}"
        problem = pose_problem(self.latest, now_ns, self.max_age_s, not self.still(), self.reach)
        if not problem:
            self.start, self._moved = self.latest, (0.0, 0.0)
        return problem

    def end_problem(self, now_ns: int) -> str:
        """Why the sweep since :meth:`start_problem` cannot enter the map ('' when it can)."""
        moved_m, moved_rad = self._moved
        if moved_m > self.tolerance_m or moved_rad > self.tolerance_rad:
            return (
                f"the arm moved during the sweep's ring-downs: {moved_m * 1e3:.3f} mm and "
                f"{math.degrees(moved_rad):.3f}° from where it started, at most "
                f"{self.tolerance_m * 1e3:.3f} mm and {math.degrees(self.tolerance_rad):.3f}°"
            )
        age_s = (now_ns - self.latest.stamp_ns) / NS_PER_S if self.latest is not None else math.inf
        if age_s > self.max_age_s:
            return f"stale pose at the sweep's end: {age_s:.3f} s old, at most {self.max_age_s:.3f} s"
        return ""


@dataclasses.dataclass(frozen=True)
class WorkspaceMap:
    """The fitted map: the ``model``, its degree's ``choice``, the sweeps' ``poses`` as the
    arm reported them and the ``settings`` it was made with."""

    model: WorkspaceModel
    choice: DegreeChoice
    poses: tuple[StampedPose, ...]
    settings: MapSettings

    def outside_problem(self, point_m: np.ndarray) -> str:
        """Why the map does not answer at ``point_m`` ('' inside its workspace ball)."""
        distance_m = float(np.linalg.norm(np.asarray(point_m, float) - np.asarray(self.settings.centre_m, float)))
        if math.isfinite(distance_m) and distance_m <= self.settings.radius_m:
            return ""
        return (
            f"the point is {distance_m * 1e3:.1f} mm from the workspace's centre, outside its "
            f"{self.settings.radius_m * 1e3:.1f} mm: the map does not extrapolate"
        )

    def rms_std(self) -> tuple[float, float]:
        """The rms σ of B (T) and of G (T/m) over points spread through the workspace ball."""
        rng = np.random.default_rng(0)
        direction = rng.normal(size=(HELD_OUT_POINTS, 3))
        direction /= np.linalg.norm(direction, axis=1)[:, None]
        radius = self.settings.radius_m * rng.uniform(0.0, 1.0, (HELD_OUT_POINTS, 1)) ** (1.0 / 3.0)
        points = np.asarray(self.settings.centre_m, float) + direction * radius
        field_std = self.model.field_t(points)[1]
        gradient_std = self.model.gradient_t_per_m(points)[1]
        return float(np.sqrt(np.mean(field_std**2))), float(np.sqrt(np.mean(gradient_std**2)))

    def report(self) -> str:
        """The map's line in the log: its sweeps, its degree's choice and its rms σ."""
        field_std, gradient_std = self.rms_std()
        return (
            f"workspace map of {len(self.poses)} sweeps: {self.choice.report()}; rms σ over the workspace "
            f"{field_std * 1e6:.3f} µT, {gradient_std * 1e6:.1f} µT/m"
        )


def sweep_observations(
    sweeps: Sequence[tuple[Decomposition, StampedPose]], probe: Probe, settings: MapSettings
) -> list[Observation]:
    """Each decomposed sweep at the pose the arm reported for it."""
    return [
        sweep_observation(d, pose.position_m, pose.plane, probe, k, settings.gravity_m_per_s2)
        for k, (d, pose) in enumerate(sweeps)
    ]


def workspace_map(
    sweeps: Sequence[tuple[Decomposition, StampedPose]], probe: Probe, settings: MapSettings
) -> WorkspaceMap:
    """The map of ``sweeps`` (module docstring); ValueError when they cannot determine one."""
    if wrong := [pose.frame_id for _, pose in sweeps if pose.frame_id != settings.frame_id]:
        raise ValueError(f"a sweep's pose is in frame {wrong[0]!r}, the map is in {settings.frame_id!r}")
    observations = sweep_observations(sweeps, probe, settings)
    values = 5 * len(observations)
    # each cross-validation fold leaves out a fifth of the sweeps: the rest must still determine it
    degrees = tuple(d for d in settings.degrees if coefficient_count(d) < 0.8 * values - 5)
    if not degrees:
        raise ValueError(f"{len(observations)} sweeps cannot determine a map of degree {min(settings.degrees)}")
    fitted = map_with_pose_error(observations, degrees, settings.accuracy, settings.centre_m, settings.radius_m)
    return WorkspaceMap(fitted.carried.model, fitted.choice, tuple(pose for _, pose in sweeps), settings)
