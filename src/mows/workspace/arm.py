"""The arm that carries the probe, as CRTK names it, and the checks a sweep's pose must pass.

Research arms that follow the Collaborative Robotics Toolkit's conventions (the dVRK's among
them) publish where their tool is as ``measured_cp`` and take a goal as ``move_cp``, both
``geometry_msgs/PoseStamped`` since CRTK 1.2, and report ``operating_state`` with ``is_busy``
while a move runs. Here a pose is :class:`StampedPose` (stamp, frame, position, unit quaternion
x, y, z, w), the ROS-free form of that message.

:class:`SimulatedArm` is such an arm, harder than a real one where it matters to a map: its
``measured_cp`` is ``latency_s`` old when it arrives, carries encoder noise, and the tool is not
where it says: every move ends off the goal by a draw of the arm's accuracy (the pose error a
map must carry, :mod:`mows.workspace.poses`); a goal outside its reach, or one sent while it is
busy, is refused with the reason. It is fed the time (I/O-free); the simulator asks it where the
probe truly is (``true_pose``).

:func:`pose_problem` is the mapper's check before it trusts a pose for a sweep: a pose older
than the sweep allows, one outside the reach, or an arm still busy (a probe moving during a
ring-down) is refused with the reason.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

from mows.workspace.poses import PoseError, rotation

NS_PER_S = 1_000_000_000


def quaternion_matrix(quaternion_xyzw: ArrayLike) -> np.ndarray:
    """The rotation matrix of a unit quaternion (x, y, z, w)."""
    x, y, z, w = np.asarray(quaternion_xyzw, float)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def matrix_quaternion(matrix: np.ndarray) -> np.ndarray:
    """A unit quaternion (x, y, z, w), w ≥ 0, of a rotation matrix."""
    m = np.asarray(matrix, float)
    w = math.sqrt(max(0.0, 1.0 + m[0, 0] + m[1, 1] + m[2, 2])) / 2.0
    x = math.copysign(math.sqrt(max(0.0, 1.0 + m[0, 0] - m[1, 1] - m[2, 2])) / 2.0, m[2, 1] - m[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - m[0, 0] + m[1, 1] - m[2, 2])) / 2.0, m[0, 2] - m[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - m[0, 0] - m[1, 1] + m[2, 2])) / 2.0, m[1, 0] - m[0, 1])
    q = np.array([x, y, z, w])
    return q / np.linalg.norm(q)


@dataclasses.dataclass(frozen=True)
class StampedPose:
    """geometry_msgs/PoseStamped without ROS: device stamp (ns), frame, position (m), unit
    quaternion (x, y, z, w). The probe's rotation plane is the tool frame's x–y plane."""

    stamp_ns: int
    frame_id: str
    position_m: np.ndarray
    orientation_xyzw: np.ndarray

    def __post_init__(self) -> None:
        position, quaternion = np.asarray(self.position_m, float), np.asarray(self.orientation_xyzw, float)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ValueError(f"a pose's position is a finite 3-vector in metres, got {self.position_m!r}")
        if quaternion.shape != (4,) or not abs(np.linalg.norm(quaternion) - 1.0) < 1e-6:
            raise ValueError(f"a pose's orientation is a unit quaternion (x, y, z, w), got {self.orientation_xyzw!r}")

    @classmethod
    def of(cls, msg) -> StampedPose:
        """From a geometry_msgs/PoseStamped, rclpy's or a bag's (read by attribute); ValueError
        for one that is not a pose (NaN, a quaternion not of unit length)."""
        p, q = msg.pose.position, msg.pose.orientation
        stamp_ns = int(msg.header.stamp.sec) * NS_PER_S + int(msg.header.stamp.nanosec)
        return cls(stamp_ns, msg.header.frame_id, np.array([p.x, p.y, p.z]), np.array([q.x, q.y, q.z, q.w]))

    @property
    def rotation(self) -> np.ndarray:
        return quaternion_matrix(self.orientation_xyzw)

    @property
    def plane(self) -> np.ndarray:
        """Rows e1, e2 of the probe's rotation plane: the tool frame's x and y axes."""
        return self.rotation[:, :2].T


@dataclasses.dataclass(frozen=True)
class Reach:
    """Where the arm can put the tool: a shell about ``base_m`` between the two radii."""

    base_m: tuple = (0.0, 0.0, -0.3)
    min_radius_m: float = 0.15
    max_radius_m: float = 0.45

    def problem(self, position_m: ArrayLike) -> str:
        """Why ``position_m`` is out of reach ('' when it is within)."""
        distance = float(np.linalg.norm(np.asarray(position_m, float) - np.asarray(self.base_m, float)))
        if distance > self.max_radius_m:
            return (
                f"outside the arm's reach: {distance * 1e3:.1f} mm from its base, at most {self.max_radius_m * 1e3:.0f}"
            )
        if distance < self.min_radius_m:
            return (
                f"inside the arm's reach: {distance * 1e3:.1f} mm from its base, at least {self.min_radius_m * 1e3:.0f}"
            )
        return ""


@dataclasses.dataclass(frozen=True)
class ArmAnswer:
    """A ``move_cp``'s answer: accepted, or refused with the reason."""

    accepted: bool
    reason: str = ""


class SimulatedArm:
    """A CRTK arm in simulated time (module docstring). ``speed_m_per_s`` and
    ``turn_rad_per_s`` set how long a move takes; ``accuracy`` is where it ends off the goal;
    ``encoder_noise`` what its reports add."""

    def __init__(
        self,
        rng: np.random.Generator,
        accuracy: PoseError,
        encoder_noise: PoseError,
        reach: Reach = Reach(),
        latency_s: float = 0.02,
        speed_m_per_s: float = 0.05,
        turn_rad_per_s: float = 1.0,
        frame_id: str = "arm_base",
    ) -> None:
        self.rng, self.accuracy, self.encoder_noise, self.reach = rng, accuracy, encoder_noise, reach
        # The encoders' own stream: where a move ends must not depend on how often the arm was read.
        self._encoder_rng = rng.spawn(1)[0]
        self.latency_s, self.speed_m_per_s, self.turn_rad_per_s, self.frame_id = (
            latency_s,
            speed_m_per_s,
            turn_rad_per_s,
            frame_id,
        )
        self._goal = StampedPose(0, frame_id, np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))
        self._start = self._goal
        self._error = np.zeros(6)
        self._departure_s = self._arrival_s = 0.0

    def is_busy(self, now_s: float) -> bool:
        """CRTK's ``operating_state.is_busy``: a move is running."""
        return now_s < self._arrival_s

    def move_cp(self, goal: StampedPose, now_s: float) -> ArmAnswer:
        """Start a move to ``goal``, or refuse it with the reason (busy, out of reach, another frame)."""
        if goal.frame_id != self.frame_id:
            return ArmAnswer(False, f"goal in frame {goal.frame_id!r}, the arm moves in {self.frame_id!r}")
        if problem := self.reach.problem(goal.position_m):
            return ArmAnswer(False, problem)
        if self.is_busy(now_s):
            return ArmAnswer(False, f"busy: the last move ends in {self._arrival_s - now_s:.2f} s")
        distance = float(np.linalg.norm(np.asarray(goal.position_m) - np.asarray(self._goal.position_m)))
        turn = float(np.arccos(np.clip((np.trace(goal.rotation.T @ self._goal.rotation) - 1) / 2, -1, 1)))
        self._start, self._departure_s = self._commanded(now_s), now_s
        self._arrival_s = now_s + max(distance / self.speed_m_per_s, turn / self.turn_rad_per_s)
        # A turn of the last joint alone (the tool's z and position kept) keeps where the tool
        # truly is off its goal: the arm's repeatability, far better than its accuracy.
        last_joint = distance == 0.0 and np.allclose(goal.rotation[:, 2], self._goal.rotation[:, 2], atol=1e-9)
        if not last_joint:
            self._error = self.rng.normal(size=6) * self.accuracy.std
        self._goal = goal
        return ArmAnswer(True)

    def true_pose(self, now_s: float) -> StampedPose:
        """Where the tool is (the simulator's truth); during a move, not yet at the goal."""
        if self.is_busy(now_s):
            raise ValueError("the tool is between poses while the arm moves")
        turn = rotation(self._error[3:]) @ self._goal.rotation
        return StampedPose(
            int(now_s * NS_PER_S),
            self.frame_id,
            np.asarray(self._goal.position_m) + self._error[:3],
            matrix_quaternion(turn),
        )

    def _commanded(self, time_s: float) -> StampedPose:
        """Where the arm's joints put the tool at ``time_s`` by its own kinematics: along the
        straight line and the shortest turn from the last pose to the goal, the goal once there."""
        span_s = self._arrival_s - self._departure_s
        share = 1.0 if span_s <= 0 else min(1.0, max(0.0, (time_s - self._departure_s) / span_s))
        start, goal = self._start, self._goal
        turn = Rotation.from_matrix(start.rotation.T @ goal.rotation).as_rotvec()
        position = np.asarray(start.position_m) + share * (np.asarray(goal.position_m) - np.asarray(start.position_m))
        return StampedPose(0, self.frame_id, position, matrix_quaternion(start.rotation @ rotation(share * turn)))

    def measured_cp(self, now_s: float) -> StampedPose:
        """What the arm reports at ``now_s``: where it believes the tool was ``latency_s`` ago
        (on its way, or at its goal once there), with encoder noise; stamped with that earlier time."""
        then_s = now_s - self.latency_s
        believed = self._commanded(then_s)
        noise = self._encoder_rng.normal(size=6) * self.encoder_noise.std
        return StampedPose(
            int(then_s * NS_PER_S),
            self.frame_id,
            np.asarray(believed.position_m) + noise[:3],
            matrix_quaternion(rotation(noise[3:]) @ believed.rotation),
        )


def pose_problem(pose: StampedPose, now_ns: int, max_age_s: float, busy: bool, reach: Reach) -> str:
    """Why ``pose`` cannot stand for a sweep that starts at ``now_ns`` ('' when it can)."""
    age_s = (now_ns - pose.stamp_ns) / NS_PER_S
    if age_s > max_age_s:
        return f"stale pose: {age_s:.3f} s old, a sweep takes poses at most {max_age_s:.3f} s old"
    if busy:
        return "the arm is moving: a ring-down needs the probe still"
    return reach.problem(pose.position_m)
