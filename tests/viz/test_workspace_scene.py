"""A workspace map in the 3D scene: B on a grid through the workspace ball, each arrow along the
field the map was fitted to (a pair of dipoles, not the map's own harmonics), its label |B| ± σ,
and one arrow per pose along the normal of its rotation plane."""

import math
from types import SimpleNamespace

import numpy as np

from mows.viz import channels
from mows.viz.view import SCENE, View
from mows.workspace.fit import fit
from mows.workspace.harmonics import SolidHarmonics
from workspace.fields import RADIUS_M, SOURCE, sweeps


def pose_msg(position, quaternion):
    p, q = (
        SimpleNamespace(x=position[0], y=position[1], z=position[2]),
        SimpleNamespace(*(), **dict(zip("xyzw", quaternion))),
    )
    return SimpleNamespace(header=SimpleNamespace(frame_id="arm_base"), pose=SimpleNamespace(position=p, orientation=q))


def map_msg():
    model = fit(sweeps(40, np.random.default_rng(3)), SolidHarmonics(6, (0.0, 0.0, 0.0), RADIUS_M))
    half = math.sqrt(0.5)
    return SimpleNamespace(
        header=SimpleNamespace(frame_id="arm_base"),
        centre_m=[0.0, 0.0, 0.0],
        scale_m=RADIUS_M,
        radius_m=RADIUS_M,
        degree=6,
        coefficients_t=model.coefficients.tolist(),
        covariance_t2=model.covariance.ravel().tolist(),
        chi2=model.chi2,
        dof=model.dof,
        # the tool frame turned 90° about x: its z, the plane's normal, along −y
        poses=[
            pose_msg((0.0, 0.0, RADIUS_M), (0.0, 0.0, 0.0, 1.0)),
            pose_msg((RADIUS_M, 0.0, 0.0), (half, 0.0, 0.0, half)),
        ],
    )


def test_the_scene_shows_the_maps_field_on_a_grid_with_sigma_and_its_poses():
    (shown,) = View().on_workspace_model(map_msg(), 1_000)
    assert shown.topic == SCENE
    field, poses = shown.content["workspace/field"], shown.content["workspace/poses"]
    tails = np.array([a.tail_m for a in field])
    assert len(field) == 33 and np.all(np.linalg.norm(tails, axis=1) <= RADIUS_M + 1e-12)  # 5³ grid, in the ball
    truth = SOURCE.field_t(tails)
    cosine = np.sum(np.array([a.direction for a in field]) * truth, axis=1) / np.linalg.norm(truth, axis=1)
    assert np.all(cosine > 1 - 1e-6)
    lengths = np.array([a.length_m for a in field])
    np.testing.assert_allclose(
        lengths / lengths.max(), np.linalg.norm(truth, axis=1) / np.linalg.norm(truth, axis=1).max(), rtol=1e-4
    )
    assert all(a.label.endswith(" µT") and " mT ± " in a.label for a in field)
    np.testing.assert_allclose([p.direction for p in poses], [[0, 0, 1], [0, -1, 0]], atol=1e-12)
    assert channels.payload(shown)  # Foxglove's scene takes both entities
