"""The 3D scene of a workspace map: the field B as arrows on a grid through the workspace ball,
each labelled |B| ± σ, and the poses the sweeps were taken at.

The map (``mows_msgs/WorkspaceModel``, or a bag's) is the solid-harmonic potential of
:mod:`mows.workspace.harmonics`; B and its σ at each grid point follow from its coefficients and
their covariance exactly as the mapper's ``field_at`` gives them. The grid is ``GRID`` points a
side over the ball's bounding cube, those inside the ball kept; the largest |B| is drawn
``GRID_SHARE`` of the grid's spacing long. Each pose is drawn as its rotation plane's normal
(the tool frame's z, the axis the probe turns about), one spacing long.
"""

from __future__ import annotations

import numpy as np

from mows.viz.scene import Arrow
from mows.workspace.fit import WorkspaceModel as FittedModel
from mows.workspace.harmonics import SolidHarmonics

GRID = 5
GRID_SHARE = 0.8


def fitted_model(msg) -> FittedModel:
    """The fitted model of a WorkspaceModel message."""
    basis = SolidHarmonics(int(msg.degree), tuple(float(c) for c in msg.centre_m), float(msg.scale_m))
    coefficients = np.asarray(msg.coefficients_t, float)
    covariance = np.asarray(msg.covariance_t2, float).reshape(coefficients.size, coefficients.size)
    return FittedModel(basis, coefficients, covariance, float(msg.chi2), int(msg.dof))


def grid_points(centre_m, radius_m: float) -> tuple[np.ndarray, float]:
    """The grid's points inside the ball, and its spacing."""
    axis = np.linspace(-radius_m, radius_m, GRID)
    cube = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.asarray(centre_m, float) + cube[np.linalg.norm(cube, axis=1) <= radius_m * (1 + 1e-9)], axis[1] - axis[0]


def workspace_arrows(msg) -> dict[str, list[Arrow]]:
    """The map's entities: ``workspace/field`` (B on the grid) and ``workspace/poses``."""
    frame = msg.header.frame_id
    points, spacing = grid_points(msg.centre_m, float(msg.radius_m))
    field, field_std = fitted_model(msg).field_t(points)
    magnitude = np.linalg.norm(field, axis=1)
    # σ of |B| along B (first order), as the probes' arrows
    along = field / np.where(magnitude > 0, magnitude, 1.0)[:, None]
    magnitude_std = np.sqrt(np.sum((along * field_std) ** 2, axis=1))
    largest = float(np.max(magnitude)) or 1.0
    arrows = [
        Arrow(frame, p, a, GRID_SHARE * spacing * m / largest, "B", f"{m * 1e3:.4g} mT ± {s * 1e6:.2g} µT")
        for p, a, m, s in zip(points, along, magnitude, magnitude_std)
    ]
    poses = []
    for pose in msg.poses:
        x, y, z, w = (
            pose.pose.orientation.x,
            pose.pose.orientation.y,
            pose.pose.orientation.z,
            pose.pose.orientation.w,
        )
        normal = np.array([2 * (x * z + y * w), 2 * (y * z - x * w), 1 - 2 * (x * x + y * y)])
        where = np.array([pose.pose.position.x, pose.pose.position.y, pose.pose.position.z])
        poses.append(Arrow(pose.header.frame_id or frame, where, normal, spacing, "pose", ""))
    return {"workspace/field": arrows, "workspace/poses": poses}
