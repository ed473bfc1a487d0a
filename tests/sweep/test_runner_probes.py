"""A sweep of three probes at once through the runner, without ROS: each cycle's ring-downs
give one fit per probe, and each probe's field comes back from its own fits.

The stand-in driver gives each probe the exact first-principles frequency of its own uniform
field (different per probe, as at different places) plus noise; each probe's decomposition must
recover its own field within 4σ, which a mix of the probes' fits would not.
"""

import math

import numpy as np
import pytest

from mows.estimate.probe_set import ProbeEntry
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from mows.sweep.events import CycleAnswer, SweepFit, SweepGoal, SweepSettings
from mows.sweep.record import SweepPoint
from mows.sweep.runner import SweepRunner, SweepState

STD_HZ = 5e-4
ANGLES = tuple(np.radians(np.arange(0.0, 360.0, 45.0)))
PROBES = tuple(
    ProbeEntry(k, P.replace(spring_nm_per_rad=P.spring_nm_per_rad * scale), P.f00_hz * math.sqrt(scale))
    for k, scale in enumerate((1.0, 1.235, 0.806))
)
FIELDS_T = (np.array([30e-6, -20e-6, 0.0]), np.array([-10e-6, 25e-6, 0.0]), np.array([5e-6, 40e-6, 0.0]))


def fit(entry, field_t, theta0_rad, cycle_id, rng, ok=True):
    f = float(ArcPotential.from_source(entry.probe, UniformField(field_t), Pose(theta0_rad=theta0_rad)).frequency_hz())
    f += STD_HZ * rng.standard_normal()
    f00 = entry.probe.f00_hz
    point = SweepPoint(theta0_rad, f, STD_HZ, f - f00, STD_HZ, math.radians(2.0), 1.8, 0.5, 100.0)
    return SweepFit(cycle_id, False, point if ok else None, f"probe {entry.probe_id}", entry.probe_id)


def run(settings, fails=()):
    """The sweep through to its decomposition; ``fails``: probe ids whose every fit fails."""
    runner, rng = SweepRunner(), np.random.default_rng(3)
    runner.start(SweepGoal(ANGLES, 2), settings)
    step, cycle = runner.begin(), 0
    while step.decompose is None:
        cycle += 1
        call = step.run_cycle
        fits = [
            fit(e, f, call.theta0_rad, cycle, rng, ok=e.probe_id not in fails)
            for _ in range(call.repeats)
            for e, f in zip(PROBES, FIELDS_T)
        ]
        assert runner.on_cycle(CycleAnswer(cycle, call.repeats)).feedback is None  # waits for every probe's
        steps = [runner.on_fit(f) for f in fits]
        assert steps[:-1] == [None] * (len(fits) - 1)
        step = steps[-1]
        assert len(step.feedback.fits) == 2 * len(PROBES)
    return runner, runner.on_decomposed(step.decompose())


def test_each_probe_is_decomposed_from_its_own_fits():
    runner, step = run(SweepSettings(probes=PROBES))
    maps = step.publish
    assert step.finished.ok and step.finished.maps == maps and step.finished.map is maps[0]
    assert [m.probe_id for m in maps] == [0, 1, 2]
    for m, entry, field in zip(maps, PROBES, FIELDS_T):
        d = m.decomposition
        assert d.ok, d.message
        assert len(m.record.points) == 2 * len(ANGLES) and m.f00_hz == pytest.approx(entry.probe.f00_hz)
        sigma = np.sqrt(np.diag(d.field_covariance_t2))
        assert np.all(np.abs(d.field_t - field[:2]) < 4 * sigma), (m.probe_id, d.field_t, field)
        # listed without places, the magnets would sit on one another: no coupling is modelled
        assert d.message.endswith(
            "decomposed without its neighbours' fields: probes 0 and 1 are listed 0.0 mm apart (position_m)"
        )
    # the fields differ by far more than σ: a probe fed another's fits would fail the check above
    assert np.abs(FIELDS_T[0] - FIELDS_T[1])[:2].min() > 100 * sigma.max()


def test_a_probe_without_a_good_fit_is_reported_and_the_others_are_decomposed():
    _, step = run(SweepSettings(probes=PROBES), fails=(1,))
    outcome = step.finished
    assert not outcome.ok and "probe 1: no successful ring-down of probe 1 (16 failed)" in outcome.message
    assert [m.decomposition.ok for m in step.publish] == [True, False, True]
    assert np.all(np.isnan(step.publish[1].decomposition.field_t))


def test_fits_of_a_probe_not_listed_do_not_complete_an_orientation():
    runner, rng = SweepRunner(), np.random.default_rng(3)
    runner.start(SweepGoal(ANGLES, 1), SweepSettings(probes=PROBES[:2]))
    call = runner.begin().run_cycle
    runner.on_cycle(CycleAnswer(1, 1))
    fits = [fit(e, f, call.theta0_rad, 1, rng) for e, f in zip(PROBES, FIELDS_T)]
    assert runner.on_fit(fits[0]) is None and runner.on_fit(fits[2]) is None  # probe 2 is not listed
    step = runner.on_fit(fits[1])
    assert step is not None and list(step.feedback.fits) == ["probe 0", "probe 1"]


def test_an_adaptive_sweep_of_several_probes_is_refused():
    goal = SweepGoal.asked((), 0, "", "B", 1e-7, 0.0, 60.0)
    with pytest.raises(ValueError, match="adaptive sweep is of one probe; 3 are listed"):
        SweepRunner().start(goal, SweepSettings(probes=PROBES))


def test_an_adaptive_sweep_of_a_list_of_one_probe_is_that_probe_s():
    goal = SweepGoal.asked((), 0, "", "B", 1e-7, 0.0, 60.0)
    runner = SweepRunner()
    runner.start(goal, SweepSettings(probes=PROBES[1:2]))
    assert runner.state == SweepState.SWEEPING
