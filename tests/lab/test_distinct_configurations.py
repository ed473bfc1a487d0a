"""The lab at scale: the potential is evaluated once per distinct configuration, and that changes
nothing (docs/model_lab.md, "Long tables").

Requirement: on a 5000-row table of 12 orientations, evaluating each distinct configuration once
and giving it to its rows yields the same χ², parameters, BIC and verdict as evaluating every row,
to 1e-9 relative. The ungrouped reference is the same arithmetic on every row (each row its own
group), so the two can differ only through the grouping: a key that left out an input h reads
would give rows another row's frequency, and the fits would differ far beyond 1e-9.
"""

import dataclasses

import numpy as np
import pytest

from mows.lab import FrequencyModel, catalog, diagnose
from mows.lab.data import synthetic
from mows.lab.model import configuration, frequency_model
from mows.physics.field import UniformField, anti_helmholtz_pair
from mows.physics.probe import PAPER_PROBE

ROWS = 5000
RTOL = 1e-9
EFFECTS = ("transverse_gradient", "finite_amplitude", "static_deflection", "moment_scale")


@pytest.fixture(scope="module")
def table():
    """12 orientations in a weak anti-Helmholtz gradient plus a tenth of the Earth's field: one
    sweep from the exact sources, repeated with fresh noise (each copy its own sweep)."""
    sweep = synthetic.rotation_sweeps(30.0, 1)
    theta0 = sweep.pop("theta0_deg")
    source = anti_helmholtz_pair((0, 0, 0), (1, 0, 0), 0.105, 100, 0.05) + UniformField((2e-6, -1.5e-6, -4e-6))
    one = synthetic.synthesize(PAPER_PROBE, source, theta0, np.random.default_rng(7), **sweep)
    copies = -(-ROWS // len(one))
    columns = {name: np.tile(values, copies)[:ROWS] for name, values in one.columns.items()}
    columns["sweep"] = np.repeat(np.arange(copies), len(one))[:ROWS].astype(float)
    columns.pop("t_s")
    columns["f_hz"] = columns["f_hz"] + np.random.default_rng(8).normal(0.0, 1.0, ROWS) * columns["f_std_hz"]
    return dataclasses.replace(one, columns=columns)


def _each_row_its_own(keys):
    rows = np.arange(len(keys))
    return rows, rows


def _fits(table, monkeypatch, grouped: bool):
    if not grouped:
        monkeypatch.setattr(configuration, "distinct_rows_of", _each_row_its_own)
        monkeypatch.setattr(frequency_model, "distinct_rows_of", _each_row_its_own)
        table = dataclasses.replace(table)  # a table of its own: nothing grouped is cached for it
    pool = [catalog()[name] for name in EFFECTS]
    base = FrequencyModel(PAPER_PROBE).fit(table)
    extended = (FrequencyModel(PAPER_PROBE) + pool[0] + pool[2]).fit(table)
    return base, extended, diagnose(base, pool)


def test_the_table_has_twelve_configurations(table):
    distinct, inverse = frequency_model.distinct_table(table)
    assert len(table) == ROWS and len(distinct) == 12
    assert np.array_equal(table.theta0_deg, distinct.theta0_deg[inverse])
    # A time column makes every row of the table distinct, but not the base model's configurations.
    timed = dataclasses.replace(table, columns={**table.columns, "t_s": np.arange(ROWS) * 10.0})
    assert len(frequency_model.distinct_table(timed)[0]) == ROWS
    first, inverse = configuration.distinct_rows(configuration.Configuration.base(timed, PAPER_PROBE))
    assert len(first) == 12 and np.array_equal(table.theta0_deg, table.theta0_deg[first][inverse])


def test_grouped_and_ungrouped_give_the_same_fits_and_verdict(table, monkeypatch):
    grouped = _fits(table, monkeypatch, grouped=True)
    ungrouped = _fits(table, monkeypatch, grouped=False)
    for one, other in zip(grouped[:2], ungrouped[:2]):
        assert one.chi2 == pytest.approx(other.chi2, rel=RTOL)
        assert one.bic == pytest.approx(other.bic, rel=RTOL)
        np.testing.assert_allclose(one.values, other.values, rtol=RTOL)
        np.testing.assert_allclose(one.prediction_hz, other.prediction_hz, rtol=RTOL)
    assert grouped[2].verdict == ungrouped[2].verdict
    assert [c.name for c in grouped[2].candidates] == [c.name for c in ungrouped[2].candidates]
    np.testing.assert_allclose(
        [c.delta_bic for c in grouped[2].candidates], [c.delta_bic for c in ungrouped[2].candidates], rtol=1e-6
    )
