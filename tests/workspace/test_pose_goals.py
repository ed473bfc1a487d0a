"""At an industrial arm's pose error (0.1 mm and 0.01° per component) 30 sweeps of an
eight-coil navigation system make a map whose G and σ meet the goals: G within 0.5 % rms, the
pulls of B and of G of sd 0.8–1.2. Its B is bounded below by what no fit can see, the mean of
the 30 sweeps' pose errors (``frame_bound``).

The sweeps are exact readouts of the Biot–Savart system (mows.sim.navigation) at the true poses
with Gaussian noise of a simulated sweep's σ, reported at poses off by a draw of the error, and
mapped as the mapper maps them (``map_with_pose_error``). One map's pulls are correlated through
its few largest pose errors and its B error through their mean (over these four draws the
pulls' sd of B ran from 0.54 to 1.20, B's error from 0.035 % to 0.082 %), so the figures are
pooled over draws of the pose errors and the noise: the pooled pulls' sd (0.96 and 0.93) is
known to about ±0.15, G's rms error (0.28 %) to ±0.01 %, B's (0.064 %) to ±0.01 %."""

import math

import numpy as np
import pytest

from mows.sim.navigation import navigation_system
from mows.workspace.poses import PoseError, frame_bound, map_with_pose_error, moved
from mows.workspace.simulated import ball_points
from workspace.fields import RADIUS_M, sweeps

# σ of a simulated sweep's Bx, By (T) and Gxx, Gxy, Gyy (T/m): 10 orientations of one ring-down
# each at 0.75 mHz (mows.workspace.simulated), as its decomposition reports them
SWEEP_STD = (0.113e-6, 0.113e-6, 46e-6, 19e-6, 46e-6)
DEGREES = tuple(range(2, 11))
ERROR = PoseError(1e-4, math.radians(0.01))
DRAWS = 4


pytestmark = pytest.mark.slow  # four maps of 30 sweeps with their pose errors: a minute of CPU


@pytest.fixture(scope="module")
def maps():
    source = navigation_system(1.5e-3, seed=0)
    points = ball_points(200, RADIUS_M, np.random.default_rng(1))
    truth = source.field_t(points), source.gradient_t_per_m(points)
    figures = []
    for draw in range(DRAWS):
        rng = np.random.default_rng(40 + draw)
        reported = [moved(obs, rng.normal(size=6) * ERROR.std) for obs in sweeps(30, rng, source=source, std=SWEEP_STD)]
        model = map_with_pose_error(reported, DEGREES, ERROR, (0.0, 0.0, 0.0), RADIUS_M).carried.model
        field, field_std = model.field_t(points)
        gradient, gradient_std = model.gradient_t_per_m(points)
        figures.append(
            {
                "b_error": np.sqrt(np.mean((field - truth[0]) ** 2) / np.mean(truth[0] ** 2)),
                "g_error": np.sqrt(np.mean((gradient - truth[1]) ** 2) / np.mean(truth[1] ** 2)),
                "b_pulls": ((field - truth[0]) / field_std).ravel(),
                "g_pulls": ((gradient - truth[1]) / gradient_std).ravel(),
                "degree": model.basis.max_degree,
            }
        )
    return figures, frame_bound(*truth, ERROR, 30)


def _rms(figures, key):
    return float(np.sqrt(np.mean([f[key] ** 2 for f in figures])))


def test_the_gradient_meets_its_goal_and_the_sigmas_are_honest(maps):
    figures, _ = maps
    # degree 7 chosen in every draw; at the degree 9 that χ² and the noise alone chose, 0.8 %
    assert _rms(figures, "g_error") <= 5e-3
    for key in ("b_pulls", "g_pulls"):
        assert 0.8 <= np.std(np.concatenate([f[key] for f in figures])) <= 1.2, key


def test_the_field_is_near_what_the_sweeps_mean_pose_error_allows(maps):
    """The 30 sweeps' mean pose error shifts and turns the whole map unseen: B's bound is 0.047 %
    at these points, and the map's B error over draws (0.064 %) stays within twice it. The
    goal of 0.05 % is not reached: the bound leaves the rest 0.02 % in squares, less than the
    sweeps' own pose errors or their noise take (``error_split``, docs/performance.md)."""
    figures, bound = maps
    assert 3e-4 < bound < 5e-4
    assert _rms(figures, "b_error") < 2.0 * bound
