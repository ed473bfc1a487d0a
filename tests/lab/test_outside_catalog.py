"""The lab on physics its catalog lacks (tests/lab/outside_catalog.py and channel_cases.py: ten
hidden effects of real MOWS physics, an independent truth by direct energy minimisation and
integrated ring-downs).

Requirements: each case is a rotation sweep in 15° steps of 60–120 rows with σf = 0.33 mHz whose
hidden term is far above the noise; its control differs only by that term; a seed redraws the
noise only. Against the lab (slow):

- on every case, ``--auto`` adds no catalog effect the truth lacks (only the exact potential's
  own: deflection, transverse gradient, amplitude, damping), ends ``unexplained_structure``, and
  the term the user's loop adds names the hidden term's family (channel × covariates): the search's
  first, or, where that pushes a free effect from physics (the induced moment), the one found
  with that effect held at physics; the plugin the lab writes for it, added back, ends at
  χ²/dof ≤ 1.5 and reads the truth to 3σ (the sweep over ten noise seeds of each case:
  docs/model_lab.md, "Outside the catalog");
- every control ends ``adequate`` with nothing but the physics its truth holds, and the search
  beyond the catalog finds nothing on any of 40 noise seeds;
- the user's physical plugin of each case explains its table and reads its parameter back, also
  written as the energy it adds where only an energy is exact.
"""

import functools

import numpy as np
import pytest

from lab.outside_catalog import CASES, INFO, NOISE_HZ, control, fitted_swing_deg, noise_free
from mows.lab import ProbeSet, analyse, analyse_discovering, discover
from mows.physics.probe import PAPER_PROBE


def on_its_worker(case, *rest):
    """One worker runs every test of a case, so that its noise-free truths (1–5 s, cached per
    process) and its control's selection are computed once, not once per xdist worker; the
    cases themselves spread over the workers (the module is several minutes of CPU)."""
    return pytest.param(case, *rest, marks=pytest.mark.xdist_group(f"outside_catalog_{case}"))


EACH_CASE = [on_its_worker(case) for case in sorted(CASES)]


@pytest.mark.parametrize("case", EACH_CASE)
def test_a_case_is_a_rotation_sweep_whose_hidden_term_is_far_above_noise(case):
    table, info = CASES[case](3)
    assert info.name == case and info.family and info.plugin_effect in info.plugin_source
    assert 60 <= len(table) <= 120
    assert np.all(table.f_std_hz == NOISE_HZ)
    steps = np.diff(np.unique(table.theta0_deg))
    np.testing.assert_allclose(steps, 15.0)
    for column in ("sweep", "t_s", "amplitude_deg", "ref_bx_t", "ref_by_t", "ref_bz_t", "ref_gxx_t_per_m"):
        assert table.has(column), column
    same, _ = CASES[case](3)
    other, _ = CASES[case](4)
    np.testing.assert_array_equal(same.f_hz, table.f_hz)
    assert np.std(other.f_hz - table.f_hz) == pytest.approx(np.sqrt(2) * NOISE_HZ, rel=0.3)
    off, off_info = control(case, 3)
    assert all(value == 0.0 for value in off_info.hidden.values())
    hidden = table.f_hz - off.f_hz  # the same noise draw: the hidden term alone
    assert np.ptp(hidden) > 10 * NOISE_HZ, np.ptp(hidden)
    for name in ("theta0_deg", "amplitude_deg", "ref_bx_t", "t_s"):
        np.testing.assert_array_equal(getattr(table, name), getattr(off, name))
    # The truth's fitted start swing is the table's to 0.0016° (module comment in outside_catalog).
    columns, _ = noise_free(case)
    assert np.abs(fitted_swing_deg(case) - columns["amplitude_deg"]).max() < 2e-3


@pytest.mark.slow  # the user's loop on every case: two --auto selections
@pytest.mark.parametrize("case", EACH_CASE)
def test_outside_the_catalog_the_labs_own_plugin_closes_the_gap(case, tmp_path):
    """``mows lab add --auto --discover``: the selection adds only the truth's own physics, the
    search names the hidden term's channel and covariates, and the plugin the lab writes and adds
    itself ends at χ²/dof ≤ 1.5 with its parameter within 3σ of the truth."""
    table, info = CASES[case](0)

    def save(term):
        path = tmp_path / f"{term.effect_name}.py"
        path.write_text(term.plugin)
        return path

    report, added = analyse_discovering(table, ProbeSet.one(PAPER_PROBE), save, cross_validate=False)
    assert added, report.diagnosis.explanation
    (term,) = added
    assert term.family == info.family, term.text()
    assert set(report.effect_names) - {term.effect_name} <= info.present, [step.change for step in report.history]
    assert report.chi2_dof <= 1.5, report.history
    if info.discovered_truth is not None:
        value, std = report.effect_parameter(f"{term.effect_name}.{term.plugin_parameter.name}")
        assert abs(value - info.discovered_truth) <= 3 * std, (value, std, info.discovered_truth)


@functools.cache
def control_selection(case):
    """The ``--auto`` selection on the control's seed 0, which two tests read: made once (the
    module runs on one worker)."""
    return analyse(control(case, 0)[0], ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)


@pytest.mark.slow  # the truth of every control and 40 fits and searches each
@pytest.mark.parametrize("case", EACH_CASE)
def test_the_search_beyond_the_catalog_finds_nothing_on_40_controls(case):
    """The model the control's selection ends with (its truth's physics), refitted on 40 noise
    draws: no term is reported on any."""
    model = control_selection(case).diagnosis.fit.model
    found = {}
    for seed in range(40):
        discovery = discover(model.fit(control(case, seed)[0]), ProbeSet.one(PAPER_PROBE))
        if discovery.terms:
            found[seed] = discovery.summary
    assert not found, found


@pytest.mark.slow  # the truth of every control (~20 s) and its --auto selection (made once, above)
@pytest.mark.parametrize("case", EACH_CASE)
def test_the_control_ends_adequate_with_only_the_physics_of_its_truth(case):
    info = control(case, 0)[1]
    report = control_selection(case)
    assert report.verdict == "adequate", (report.chi2_dof, report.diagnosis.explanation)
    assert set(report.effect_names) <= info.present, report.effects


PLUGINS = [on_its_worker(case, "physical") for case in sorted(CASES)] + [
    on_its_worker(case, "energy") for case in sorted(name for name, info in INFO.items() if info.energy_plugin_source)
]


@pytest.mark.slow  # an --auto selection with the plugin on every case
@pytest.mark.parametrize(("case", "form"), PLUGINS)
def test_the_users_plugin_explains_the_case(case, form, tmp_path):
    """The user's plugin in its physical form, and, where only an energy is exact (induced
    moment, quartic hinge), written as that energy (``energy_j``)."""
    table, info = CASES[case](0)
    path = tmp_path / f"{info.plugin_effect}.py"
    path.write_text(info.energy_plugin_source if form == "energy" else info.plugin_source)
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, plugins=[str(path)], cross_validate=False)
    assert info.plugin_effect in report.effect_names, report.effects
    assert set(report.effect_names) - {info.plugin_effect} <= info.present, report.effects
    assert report.chi2_dof <= 1.5, report.chi2_dof
    for name, truth in info.plugin_truth.items():
        value, std = report.effect_parameter(f"{info.plugin_effect}.{name}")
        assert abs(value - truth) <= 3 * std, (name, value, std, truth)
