"""The lab holds every fit to what physics and the probe file allow (mows.lab.diagnosis.plausibility).

Requirements: a moment 13 % off the probe file's, which states m/kM to 1 % (the default), is a
finding and not an effect: the `moment_scale` candidate says what it would need (the true error,
more than 10 σ from the file), the verdict reports it as a finding, and `--auto` never adds it;
a probe file that states m/kM only to 20 % lets the same candidate stand. Gravity's size a·g·l is
known: 0.21 mT of unreferenced field at 45° would need an in-plane "down" of length 1.37, which
no tilt gives. A curvature that the reference's field sources do not make at the probe (a
Helmholtz pair's centre) is a finding too, and physics where they do. Truths from exact sources
(mows.lab.data.synthetic), 2° ring-downs, σf = 0.33 mHz (1 mHz for the curvature).
"""

import dataclasses

import numpy as np

from mows.lab import FrequencyModel, ProbeSet, analyse, catalog
from mows.lab.data import synthetic
from mows.lab.data.reference import curvature_columns
from mows.lab.diagnosis.plausibility import conflicts
from mows.physics.field import UniformField
from mows.physics.loops import helmholtz_pair
from mows.physics.probe import PAPER_PROBE
from mows.physics.sources import PointDipole

FIELD_T = (4e-4, 1.5e-4, -4e-5)
SCALE_ERROR = 0.13


def _table(probe, source, reference=None, seed=0):
    sweep = synthetic.rotation_sweeps(15.0, 3)
    theta0 = sweep.pop("theta0_deg")
    return synthetic.synthesize(
        probe, source, theta0, np.random.default_rng(seed), 3.3e-4, 2.0, reference=reference, **sweep
    )


def test_a_moment_far_off_the_calibration_is_a_finding_not_an_effect():
    true_probe = dataclasses.replace(PAPER_PROBE, moment_am2=PAPER_PROBE.moment_am2 * (1.0 + SCALE_ERROR))
    table = _table(true_probe, UniformField(FIELD_T))
    report = analyse(table, ProbeSet.one(PAPER_PROBE), cross_validate=False)
    candidate = next(c for c in report.candidates if c.name == "moment_scale")
    assert not candidate.strong
    (conflict,) = candidate.chosen.conflicts
    assert conflict.parameter == "moment_scale.scale_error" and conflict.sigmas > 10.0, conflict
    assert abs(conflict.value - SCALE_ERROR) < 0.02, conflict  # what it would need: the true error
    assert "Finding: moment_scale would take" in report.diagnosis.explanation, report.diagnosis.explanation
    automatic = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert "moment_scale" not in automatic.effect_names, [step.change for step in automatic.history]

    stated = analyse(table, ProbeSet.one(dataclasses.replace(PAPER_PROBE, beta0_rel_std=0.2)), cross_validate=False)
    candidate = next(c for c in stated.candidates if c.name == "moment_scale")
    assert candidate.strong and not candidate.chosen.conflicts, candidate.would_need


def test_gravity_cannot_stand_in_for_a_field_it_would_need_more_than_g_for():
    """a·g·l/m = 154 µT: (0.15, 0.15) mT of unreferenced field needs d = (0.97, 0.97)."""
    hidden = UniformField((1.5e-4, 1.5e-4, 0.0))
    table = _table(PAPER_PROBE, UniformField(FIELD_T) + hidden, reference=UniformField(FIELD_T))
    fit = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + catalog()["gravity"]).fit(table)
    found = {c.parameter: c for c in conflicts(fit, ProbeSet.one(PAPER_PROBE))}
    assert found["|gravity.down|"].value > 1.3 and found["|gravity.down|"].sigmas > 10.0, found
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert "gravity" not in report.effect_names, [step.change for step in report.history]


def test_gravity_and_a_plane_tilt_must_be_one_tilt():
    """The reference is tilted by 0.05 rad about x against the plane, so that its Bz (−0.4 mT in
    two sweeps, +0.4 mT in the third) leaks into y', and a field the reference misses, 46 µT
    along x, looks like gravity with d = (0.3, 0). A level reference tilted so would put
    gravity's in-plane part at (0, 0.05): the two disagree on the plane's tilt."""
    tilt_x_rad = 0.05
    rotation = np.array(
        [[1.0, 0.0, 0.0], [0.0, np.cos(tilt_x_rad), -np.sin(tilt_x_rad)], [0.0, np.sin(tilt_x_rad), np.cos(tilt_x_rad)]]
    )
    hidden = 0.3 * 154e-6 * np.array([1.0, 0.0, 0.0])
    references = [np.array([4e-4, 1.5e-4, -4e-4 if row < 48 else 4e-4]) for row in range(72)]
    truth = [UniformField(tuple(rotation @ reference + hidden)) for reference in references]
    table = _table(PAPER_PROBE, truth, reference=[UniformField(tuple(reference)) for reference in references])
    effects = catalog()
    fit = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effects["gravity"] + effects["plane_tilt"]).fit(table)
    tilt = fit.effect_parameters("plane_tilt")[0]
    assert abs(tilt.value - tilt_x_rad) < 5 * tilt.std + 0.005, tilt  # the tilt is determined
    found = [c for c in conflicts(fit, ProbeSet.one(PAPER_PROBE)) if c.parameter.endswith("(the plane tilt's)")]
    assert found and max(c.sigmas for c in found) > 10.0, conflicts(fit, ProbeSet.one(PAPER_PROBE))
    alone = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effects["plane_tilt"]).fit(table)
    assert not [c for c in conflicts(alone, ProbeSet.one(PAPER_PROBE)) if "plane tilt" in c.parameter]


def _curvature_table(reference):
    """0.45 mT of a Helmholtz pair and a small magnet 3 cm off the probe, whose field and gradient
    the reference columns hold but whose curvature (−0.25 and 0.49 T/m²) only its source knows;
    the curvature columns as ``--reference`` would give them for ``reference``."""
    pair = helmholtz_pair((0.0, 0.0, 0.0), (1.0, 0.0, 0.0), 0.1, 100, 0.5)
    magnet = PointDipole((0.0, 5e-3, 0.0), (0.0, 0.03, 0.0))
    sweep = synthetic.rotation_sweeps(15.0, 2)
    theta0 = sweep.pop("theta0_deg")
    table = synthetic.synthesize(PAPER_PROBE, pair + magnet, theta0, np.random.default_rng(0), 1e-3, 2.0, **sweep)
    return table.with_columns(**curvature_columns(pair + magnet if reference == "truth" else pair, len(table)))


def test_a_curvature_the_references_sources_cannot_make_is_a_finding_not_an_effect():
    """The pair alone has no curvature at its centre (0 ± 0.0015 T/m² over 5 mm): the curvature
    the table needs is reported, and --auto does not take it; with the magnet in the reference's
    sources the same curvature is physics and is added."""
    report = analyse(_curvature_table("pair"), ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert "field_curvature" not in report.effect_names, [step.change for step in report.history]
    candidate = next(c for c in report.candidates if c.name == "field_curvature")
    needed = {c.parameter: c for c in candidate.chosen.conflicts}
    assert needed["field_curvature.hyyy_t_per_m2"].sigmas > 5.0, needed
    assert abs(needed["field_curvature.hyyy_t_per_m2"].value - 0.494) < 0.15, needed
    physics = analyse(_curvature_table("truth"), ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert "field_curvature" in physics.effect_names, [step.change for step in physics.history]


def test_a_curvature_added_by_hand_at_an_impossible_value_is_not_adequate():
    """The user adds the curvature to the physics that is there: the residuals become noise, but
    the verdict reports the value the pair's centre cannot have instead of accepting it."""
    known = ["finite_amplitude (at physics)", "static_deflection (at physics)", "transverse_gradient (at physics)"]
    table = _curvature_table("pair")
    added = analyse(
        table, ProbeSet.one(PAPER_PROBE), effects=[*known, "field_curvature"], rank=False, cross_validate=False
    )
    assert added.verdict == "inconsistent_physics", added.diagnosis.explanation
    assert "would need field_curvature.hyyy_t_per_m2" in added.diagnosis.explanation
    assert added.fit.chi2_dof < 1.5  # what the statistics alone would have called adequate
    physics = analyse(
        _curvature_table("truth"), ProbeSet.one(PAPER_PROBE), effects=[*known, "field_curvature"], rank=False
    )
    assert physics.verdict == "adequate", physics.diagnosis.explanation
