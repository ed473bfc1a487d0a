"""Rows the potential cannot evaluate are named with the reason and left out, never a giant χ².

The potential is expanded over ±0.75 rad (43°) of the lever's swing; a start amplitude beyond
that, or a field against the probe axis stronger than kM/m (15.3 mT for the paper's probe:
the field spring cancels the mechanical one), has no frequency in the model.
"""

import numpy as np

from mows.cli.main import main
from mows.lab import FrequencyModel, ProbeSet, analyse, catalog
from mows.lab.data import synthetic
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE

WIDE_ROWS = [2, 5]  # amplitude 50°: beyond the 43° of the expansion
UNSTABLE_ROW = 9  # 30 mT against the probe axis: k = kM + m·Bx' < 0


def _table():
    sweep = synthetic.rotation_sweeps(30.0, 2)
    theta0 = sweep.pop("theta0_deg")
    table = synthetic.synthesize(
        PAPER_PROBE, UniformField((2e-5, 1e-5, 0.0)), theta0, np.random.default_rng(1), amplitude_deg=20.0, **sweep
    )
    amplitude = table.amplitude_deg.copy()
    amplitude[WIDE_ROWS] = 50.0
    bx, by = table.ref_bx_t.copy(), table.ref_by_t.copy()
    axis_rad = np.radians(table.theta0_deg[UNSTABLE_ROW])
    bx[UNSTABLE_ROW], by[UNSTABLE_ROW] = -0.03 * np.cos(axis_rad), -0.03 * np.sin(axis_rad)
    return table.with_columns(amplitude_deg=amplitude, ref_bx_t=bx, ref_by_t=by)


def test_analyse_names_the_rows_it_leaves_out_and_fits_the_rest():
    table = _table()
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert report.n == len(table) - 3
    wide = next(note for note in report.notes if "rows 3, 6 " in note)
    assert "50" in wide and "43" in wide and "beyond" in wide
    unstable = next(note for note in report.notes if "row 10 " in note)
    assert "no stable rest angle" in unstable
    # The remaining rows are the truth plus 1 mHz noise: a sane χ², no penalty residuals.
    assert report.base.ok and np.isfinite(report.base.chi2_dof) and report.base.chi2_dof < 50
    assert report.fit.ok and report.chi2_dof < 2.0


def test_a_direct_fit_over_such_rows_is_not_ok_and_says_where():
    table = _table()
    fit = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + catalog()["finite_amplitude"].at_physics()).fit(table)
    assert fit.status.name == "BAD_FIT" and not fit.ok
    assert set(WIDE_ROWS + [UNSTABLE_ROW]) <= set(fit.invalid_rows.tolist())
    text = fit.report()
    assert "χ² not meaningful" in text and "rows 3, 6, 10" in text


def test_the_cli_prints_the_note_and_no_giant_chi2(tmp_path, capsys):
    path = tmp_path / "bad.csv"
    _table().to_csv(path)
    assert main(["lab", "compare", str(path)]) == 0
    out = capsys.readouterr().out
    assert "note: left out rows 3, 6 (data rows, 1-based)" in out
    assert "note: left out row 10 (data rows, 1-based): no stable rest angle" in out
    assert "e+" not in out.split("verdict:")[0].split("χ²/dof =")[1][:12]
