"""The lab at scale: the model is evaluated once per configuration group and fitted on the
groups' exact sufficient statistics, and that changes nothing (docs/model_lab.md, "Long tables").

Requirement: on a 5000-row table of 12 orientations, fitting the groups' weighted means, weights
and within-group χ² yields the same χ², parameters, σ, BIC, cross-validated error and verdict
as fitting every row, to 1e-9 relative. The ungrouped reference is the same arithmetic with each
row its own group (its within-group χ² is 0, its residuals those of the rows), so the two can
differ only through the grouping: a key that left out a column the model reads would give rows
another row's frequency, and the fits would differ far beyond 1e-9. An effect that reads a
per-row column (time) puts that column into the key, so its rows stay rows.
"""

import dataclasses

import numpy as np
import pytest

from mows.lab import FrequencyModel, ProbeSet, catalog, diagnose
from mows.lab.data import synthetic
from mows.lab.model import configuration, factors, frequency_model
from mows.lab.model.effects import Effect, Parameter
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
    rows = np.arange(len(keys[0]))
    return rows, rows


def _fits(table, monkeypatch, grouped: bool):
    if not grouped:
        monkeypatch.setattr(configuration, "distinct_rows_of", _each_row_its_own)
        monkeypatch.setattr(factors, "distinct_rows_of", _each_row_its_own)
        monkeypatch.setattr(frequency_model, "distinct_rows_of", _each_row_its_own)
        table = dataclasses.replace(table)  # a table of its own: nothing grouped is cached for it
    pool = [catalog()[name] for name in EFFECTS]
    probes = ProbeSet.one(PAPER_PROBE)
    base = FrequencyModel(probes).fit(table)
    extended = (FrequencyModel(probes) + pool[0] + pool[2]).fit(table)
    return base, extended, diagnose(base, pool, probes)


def test_the_table_has_twelve_configurations(table):
    distinct, inverse = FrequencyModel(ProbeSet.one(PAPER_PROBE)).groups(table)
    assert len(table) == ROWS and len(distinct) == 12
    assert np.array_equal(table.theta0_deg, distinct.theta0_deg[inverse])


def test_a_column_that_an_effect_reads_keys_the_groups(table):
    """A time column splits nothing for a model that does not read it; with spring_drift, which
    reads it, every row is its own group, and the fit follows a drift the data carry."""
    timed = table.with_columns(t_s=np.arange(ROWS) * 10.0)
    base = FrequencyModel(ProbeSet.one(PAPER_PROBE))
    drifting = base + catalog()["spring_drift"]
    assert "t_s" not in base.read_columns(timed) and "t_s" in drifting.read_columns(timed)
    assert len(base.groups(timed)[0]) == 12 and len(drifting.groups(timed)[0]) == ROWS
    first, inverse = factors.distinct_rows(configuration.Configuration.base(timed, PAPER_PROBE))
    assert len(first) == 12 and np.array_equal(table.theta0_deg, table.theta0_deg[first][inverse])
    # kM·(1 + r·t) scales f by √(1 + r·t) where the field spring is small (here 1e-4 of kM)
    rate_per_s = 4e-8
    drifted = timed.with_columns(f_hz=timed.f_hz * np.sqrt(1 + rate_per_s * timed.t_s))
    fit = drifting.fit(drifted)
    value, std = fit.values[1], fit.std[1]
    assert abs(value - rate_per_s) < 5 * std < 0.1 * rate_per_s


def test_an_effect_that_reads_every_column_keys_the_groups_by_all(table):
    def read_all(config, rows, probe, strength):
        config.frequency_hz = config.frequency_hz + strength * sum(rows.columns.values())

    effect = Effect("reads_all", "test", "", "", (Parameter("strength", "Hz", -1, 1, 1e-3),), read_all)
    model = FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effect
    assert model.read_columns(table) == set(table.columns) - set(frequency_model.MEASURED)


def test_grouped_and_ungrouped_give_the_same_fits_and_verdict(table, monkeypatch):
    grouped = _fits(table, monkeypatch, grouped=True)
    ungrouped = _fits(table, monkeypatch, grouped=False)
    assert len(grouped[0].group_model_hz) == 12 and len(ungrouped[0].group_model_hz) == ROWS
    for one, other in zip(grouped[:2], ungrouped[:2]):
        assert one.chi2 == pytest.approx(other.chi2, rel=RTOL)
        assert one.bic == pytest.approx(other.bic, rel=RTOL)
        np.testing.assert_allclose(one.values, other.values, rtol=RTOL)
        # static_deflection moves f by 1e-10 of itself here, so its forward difference, and the
        # σ that comes from it, carry the rounding of f (1e-16, which differs in the last bit
        # between a 12-row and a 5000-row evaluation) magnified 1e10-fold: 1e-6.
        np.testing.assert_allclose(one.std, other.std, rtol=RTOL if one.k == 1 else 1e-6)
        np.testing.assert_allclose(one.prediction_hz, other.prediction_hz, rtol=RTOL)
        # χ² of the sufficient statistics is that of the rows, summed here row by row
        pulls = (table.f_hz - one.model.predict(table, one.values)) / table.f_std_hz
        assert one.chi2 == pytest.approx(float(pulls @ pulls), rel=RTOL)
    assert grouped[0].cross_validate() == pytest.approx(ungrouped[0].cross_validate(), rel=RTOL)
    assert grouped[2].verdict == ungrouped[2].verdict
    assert [c.name for c in grouped[2].candidates] == [c.name for c in ungrouped[2].candidates]
    np.testing.assert_allclose(
        [c.delta_bic for c in grouped[2].candidates], [c.delta_bic for c in ungrouped[2].candidates], rtol=1e-6
    )
