"""A URDF's frames at the stage's angle: what robot_state_publisher makes of the probe mount
(mows_bringup/urdf/mows_probe_mount.urdf) and /mows/joint_states, for a viewer without TF.

Each joint gives its child's pose in its parent's frame: the ``origin`` (xyz, then the fixed-axis
roll, pitch, yaw of URDF), then for a continuous or revolute joint a turn by the joint's
position about its ``axis``. A ``mimic`` joint takes its leader's position (× multiplier +
offset). Rotations are unit quaternions (x, y, z, w).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

TURNING = ("continuous", "revolute")


@dataclass(frozen=True)
class FrameTransform:
    """The pose of ``child`` in ``parent``: a translation (m) and a rotation (x, y, z, w)."""

    parent: str
    child: str
    translation_m: NDArray[np.float64]
    rotation: NDArray[np.float64]


@dataclass(frozen=True)
class Joint:
    name: str
    kind: str
    parent: str
    child: str
    xyz_m: NDArray[np.float64]
    rpy_rad: NDArray[np.float64]
    axis: NDArray[np.float64]
    mimic: tuple[str, float, float] | None  # leader, multiplier, offset


def quaternion_rpy(roll_rad: float, pitch_rad: float, yaw_rad: float) -> NDArray[np.float64]:
    """URDF's rpy (about the fixed x, then y, then z) as a quaternion (x, y, z, w)."""
    cr, sr = math.cos(roll_rad / 2), math.sin(roll_rad / 2)
    cp, sp = math.cos(pitch_rad / 2), math.sin(pitch_rad / 2)
    cy, sy = math.cos(yaw_rad / 2), math.sin(yaw_rad / 2)
    return np.array(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ]
    )


def quaternion_axis(axis, angle_rad: float) -> NDArray[np.float64]:
    unit = np.asarray(axis, float) / np.linalg.norm(axis)
    return np.append(unit * math.sin(angle_rad / 2), math.cos(angle_rad / 2))


def multiply(q: NDArray[np.float64], r: NDArray[np.float64]) -> NDArray[np.float64]:
    """The rotation q·r (r first), quaternions (x, y, z, w)."""
    (x1, y1, z1, w1), (x2, y2, z2, w2) = q, r
    return np.array(
        [
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
        ]
    )


def _vector(element, attribute: str, default: str) -> NDArray[np.float64]:
    text = element.get(attribute, default) if element is not None else default
    return np.array([float(x) for x in text.split()])


def _link(joint: ET.Element, role: str) -> str:
    """The link a joint's ``parent`` or ``child`` names; ValueError naming the joint without one."""
    element = joint.find(role)
    if element is None or not element.get("link"):
        raise ValueError(f"joint {joint.get('name', '')!r} has no {role} link")
    return str(element.get("link"))


class Mount:
    """The joints of a URDF (its text); :meth:`transforms` at given joint positions."""

    def __init__(self, urdf_text: str):
        try:
            robot = ET.fromstring(urdf_text)
        except ET.ParseError as error:  # a SyntaxError, not a ValueError: said as the file's fault
            raise ValueError(f"not a URDF: XML error: {error}") from None
        self.joints = []
        for joint in robot.iter("joint"):
            origin, mimic = joint.find("origin"), joint.find("mimic")
            self.joints.append(
                Joint(
                    joint.get("name", ""),
                    joint.get("type", "fixed"),
                    _link(joint, "parent"),
                    _link(joint, "child"),
                    _vector(origin, "xyz", "0 0 0"),
                    _vector(origin, "rpy", "0 0 0"),
                    _vector(joint.find("axis"), "xyz", "1 0 0"),
                    None
                    if mimic is None
                    else (mimic.get("joint", ""), float(mimic.get("multiplier", 1)), float(mimic.get("offset", 0))),
                )
            )

    def transforms(self, positions: dict[str, float]) -> list[FrameTransform]:
        """Every joint's child in its parent, turning joints at ``positions`` (rad, by joint
        name; a joint not given, and not mimicking one that is, at 0)."""
        found = []
        for joint in self.joints:
            rotation = quaternion_rpy(*joint.rpy_rad)
            if joint.kind in TURNING:
                if joint.mimic is not None:
                    leader, multiplier, offset = joint.mimic
                    angle = positions.get(leader, 0.0) * multiplier + offset
                else:
                    angle = positions.get(joint.name, 0.0)
                rotation = multiply(rotation, quaternion_axis(joint.axis, angle))
            found.append(FrameTransform(joint.parent, joint.child, joint.xyz_m, rotation))
        return found
