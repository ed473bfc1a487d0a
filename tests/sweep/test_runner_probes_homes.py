"""The mapper's sweep of three probes on one stage at different home orientations.

Requirement: the runner commands the stage's angles, and each probe's fits come back at its own
θ0, the stage's angle plus its home orientation (0°, 40° and 80°). Each probe's decomposition
takes its ring-downs' θ0 from its own fits, and its neighbours' moments at a ring-down are
turned to *their* θ0 at the same step, from their fits of that step, or, where a neighbour's
fit failed, from the stage's angle plus that neighbour's home orientation. Each probe's external
B and G must then lie within the bounds of tests/sweep/test_runner_probes_coupled.py (3σ per
component, χ²/dof ≤ 2), with one probe's fits failing at one step. The stand-in driver is that
test's: each probe's frequency is the exact one of the scene with the neighbours at their
coupled rest, at their own orientations, plus noise.
"""

import math

import numpy as np
import pytest

from mows.physics.coupling import PlacedProbe, coupled_frequencies_hz
from mows.physics.pose import Pose
from mows.sweep.events import CycleAnswer, SweepFit, SweepGoal, SweepSettings
from mows.sweep.probes import decompose_probes, step_orientations_rad
from mows.sweep.record import SweepPoint
from mows.sweep.runner import SweepRunner

from .test_runner_probes_coupled import ANGLES, PROBES, REPEATS, SCENE, STD_HZ, z_scores

HOME_RAD = np.radians([0.0, 40.0, 80.0])
FAILS = (1, 3)  # probe 1's fits fail at the fourth orientation


def fits(stage_rad, cycle_id, step, rng):
    placed = [
        PlacedProbe(e.probe, Pose(magnet_position_m=e.position_m, theta0_rad=stage_rad + h))
        for e, h in zip(PROBES, HOME_RAD)
    ]
    frequencies = coupled_frequencies_hz(placed, SCENE)
    out = []
    for _ in range(REPEATS):
        for entry, p, f in zip(PROBES, placed, frequencies):
            f += STD_HZ * rng.standard_normal()
            theta0 = p.pose.theta0_rad
            point = SweepPoint(theta0, f, STD_HZ, f - entry.f00_hz, STD_HZ, math.radians(2.0), 1.8, 0.5, cycle_id)
            failed = (entry.probe_id, step) == FAILS
            out.append(SweepFit(cycle_id, False, None if failed else point, None, entry.probe_id))
    return out


@pytest.fixture(scope="module")
def swept():
    runner, rng = SweepRunner(), np.random.default_rng(5)
    runner.start(SweepGoal(ANGLES, REPEATS), SweepSettings(probes=PROBES))
    step, cycle, feedback = runner.begin(), 0, []
    while step.decompose is None:
        cycle += 1
        runner.on_cycle(CycleAnswer(cycle, REPEATS))
        step = [runner.on_fit(f) for f in fits(step.run_cycle.theta0_rad, cycle, cycle - 1, rng)][-1]
        feedback.append(step.feedback)
    return step, runner.on_decomposed(step.decompose()), feedback


def test_each_probes_external_field_and_gradient_at_its_own_orientations(swept):
    _, done, _ = swept
    assert done.finished.ok and [m.probe_id for m in done.publish] == [0, 1, 2]
    decompositions = [m.decomposition for m in done.publish]
    z = z_scores(decompositions)
    print("z (Bx, By, Gxx, Gxy, Gyy):\n", np.round(z, 2))
    print("χ²/dof:", [round(d.chi2_dof, 2) for d in decompositions])
    assert np.all(np.abs(z) < 3.0) and all(d.chi2_dof < 2.0 for d in decompositions)
    assert len(done.publish[1].record.points) == REPEATS * (len(ANGLES) - 1)


def test_the_neighbours_orientations_are_theirs_at_each_step(swept):
    step, _, _ = swept
    sweeps = step.decompose.args[0]
    steps = {s.probe_id: s.steps for s in sweeps}
    table = step_orientations_rad(sweeps, np.array(ANGLES))
    assert np.array_equal(step.decompose.keywords["orientations_rad"], table)
    expected = np.array(ANGLES) + HOME_RAD[:, None]
    assert np.allclose(np.angle(np.exp(1j * (table - expected))), 0.0, atol=1e-12)  # probe 1's failed step too
    assert 3 not in steps[1] and list(steps[0]) == [j for j in range(len(ANGLES)) for _ in range(REPEATS)]
    # The control: the neighbours turned to the stage's angle, their home orientations left out.
    at_stage = decompose_probes(sweeps, orientations_rad=np.array([ANGLES] * len(PROBES)))
    z = z_scores(at_stage)
    print("z with the neighbours at the stage's angle:\n", np.round(z, 2))
    assert np.abs(z).max() > 8.0


def test_the_feedback_shift_is_the_first_probes_at_its_own_orientation(swept):
    _, _, feedback = swept
    assert all(f.n_ok == REPEATS and math.isfinite(f.shift_hz) for f in feedback)
    assert [f.theta0_rad for f in feedback] == list(ANGLES)
