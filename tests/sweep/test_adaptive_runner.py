"""An adaptive sweep in the sweep runner (a goal with a target), driven without ROS: a stand-in
driver answers each planned cycle with fits whose frequencies come from the full potential of a
known uniform field, stamped as a device clock that advances by the turn and the ring-downs."""

import math

import numpy as np
import pytest

from mows.estimate.probe_set import own_probe_entry
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.events import CycleAnswer, SweepFit, SweepGoal, SweepSettings
from mows.sweep.planner import PrecisionGoal
from mows.sweep.record import SweepPoint
from mows.sweep.runner import SweepRunner

OWN = (own_probe_entry(P),)  # the runner's probe: a set of one

FIELD_T = np.array([30e-6, -20e-6, 0.0])
SETTINGS = SweepSettings(probes=OWN, repeat_s=0.8, turn_s=0.5)
MAX_STEPS = 500  # bound for a sweep that never ends (a bug)


def std_hz(theta0_rad):
    """Ring-downs near 90°/270° are 5× less precise (the signal is at 2f there)."""
    return 2e-4 * (1.0 + 4.0 * math.sin(theta0_rad) ** 4)


def sweep(goal, seed=0):
    """Run an adaptive sweep to its end: (outcome, the cycles asked for, device seconds used)."""
    rng = np.random.default_rng(seed)
    source = UniformField(FIELD_T)
    runner = SweepRunner()
    runner.start(SweepGoal(target=goal), SETTINGS)
    step, clock, cycles = runner.begin(), 0.0, []
    for cycle_id in range(1, MAX_STEPS):
        if step.finished is not None:
            return step.finished, cycles, clock
        if step.decompose is not None:
            step = runner.on_decomposed(step.decompose())
            continue
        call = step.run_cycle
        cycles.append(call)
        clock += SETTINGS.turn_s
        f_true = float(ArcPotential.from_source(P, source, Pose(theta0_rad=call.theta0_rad)).frequency_hz())
        for _ in range(call.repeats):
            sigma = std_hz(call.theta0_rad)
            f = f_true + sigma * rng.standard_normal()
            point = SweepPoint(call.theta0_rad, f, sigma, f - P.f00_hz, sigma, math.radians(2.0), 1.8, 0.5, clock)
            clock += SETTINGS.repeat_s
            assert runner.on_fit(SweepFit(cycle_id, False, point)) is None
        step = runner.on_cycle(CycleAnswer(cycle_id, call.repeats))
    raise AssertionError("the sweep did not end")


def test_an_adaptive_sweep_stops_at_its_target_with_the_field_right():
    goal = PrecisionGoal("B", field_std_t=80e-9)
    outcome, cycles, _ = sweep(goal)
    assert outcome.ok, outcome.message
    d = outcome.map.decomposition
    std = np.sqrt(np.diag(d.field_covariance_t2))
    assert np.all(std <= goal.field_std_t)
    assert np.all(np.abs(d.field_t - FIELD_T[:2]) < 4 * std), d.report()
    # Ring-downs near 90°/270° carry 25× less information: few of them are asked for.
    repeats = np.array([c.repeats for c in cycles])
    weak = np.abs(np.cos(np.array([c.theta0_rad for c in cycles]))) < math.cos(math.radians(70.0))
    assert repeats[weak].sum() < repeats.sum() / 4, [(round(math.degrees(c.theta0_rad)), c.repeats) for c in cycles]


def test_an_adaptive_sweep_keeps_its_budget():
    goal = PrecisionGoal("both", field_std_t=1e-9, gradient_std_t_per_m=1e-6, budget_s=20.0)
    outcome, _, used_s = sweep(goal, seed=1)
    assert not outcome.ok and "budget" in outcome.message
    assert used_s <= goal.budget_s


def test_an_adaptive_goal_the_decomposition_cannot_meet_is_refused():
    runner = SweepRunner()
    with pytest.raises(ValueError, match="Gxx"):
        runner.start(SweepGoal(target=PrecisionGoal("gxx")), SweepSettings(probes=OWN, f00_free=True))
    assert runner.state == "idle"


def test_a_goal_as_a_client_words_it():
    """RotationSweep's fields: no target quantity is no adaptive sweep; a zero σ takes the
    default target, a zero budget means none."""
    assert SweepGoal.asked((0.1, 0.2), 3, "paper") == SweepGoal((0.1, 0.2), 3, "paper", None)
    defaults = PrecisionGoal()
    goal = SweepGoal.asked(target="B", field_std_t=5e-9)
    assert goal.target == PrecisionGoal("B", 5e-9, defaults.gradient_std_t_per_m, math.inf)
    goal = SweepGoal.asked(target="both", gradient_std_t_per_m=2e-6, budget_s=30.0)
    assert goal.target == PrecisionGoal("both", defaults.field_std_t, 2e-6, 30.0)
    with pytest.raises(ValueError, match="quantity"):
        SweepGoal.asked(target="bz")
    with pytest.raises(ValueError, match="budget_s"):
        SweepGoal.asked(target="B", budget_s=-1.0)
