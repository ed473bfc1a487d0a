"""One probe is a probe set of one: the lab takes the same path for it as for several.

Requirement: a table of one probe gives the same fit whether its rows name their probe (the
column ``probe``, a :class:`ProbeSet` named by id) or not (``ProbeSet.one``): the same
parameter values, uncertainties, χ² and diagnosis, only the f00's name telling them apart.
The truth is the table without the column; nothing here compares the code with itself on one
path.
"""

import dataclasses

import numpy as np
import pytest

from mows.lab import FrequencyModel, MeasurementTable, ProbeSet, TableError, catalog, diagnose, effect, with_probes
from mows.lab.data import synthetic
from mows.lab.data.probe_rows import probe_parts
from mows.lab.diagnosis.physical_aliases import amplitude_scale_error
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE, Probe

from .tables import tilted_table


@pytest.fixture(scope="module")
def table():
    return tilted_table()


def test_a_probe_named_by_its_column_fits_as_the_table_without_it(table):
    named, probes = with_probes(table.with_columns(probe=np.full(len(table), 3.0)), ProbeSet.one(PAPER_PROBE))
    alone, one = with_probes(table, ProbeSet.one(PAPER_PROBE))
    assert probes.ids == (3,) and one.f00_names == ["f00_hz"]
    gravity = catalog()["gravity"]
    by_column = (FrequencyModel(probes) + gravity).fit(named)
    by_itself = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + gravity).fit(alone)
    assert by_column.model.parameter_names == ["probe_3.f00_hz", "gravity.down_x", "gravity.down_y"]
    assert by_itself.model.parameter_names[1:] == by_column.model.parameter_names[1:]
    np.testing.assert_allclose(by_column.values, by_itself.values, rtol=1e-9)
    # The off-diagonal terms are 1e-6 of the diagonal: compared on the diagonal's scale.
    scale = np.max(np.diag(by_itself.covariance))
    np.testing.assert_allclose(by_column.covariance, by_itself.covariance, rtol=1e-6, atol=1e-6 * scale)
    assert by_column.chi2 == pytest.approx(by_itself.chi2, rel=1e-9)


def test_every_row_of_a_table_without_the_column_is_its_one_probe(table):
    ((rows, part, entry),) = probe_parts(table, ProbeSet.one(PAPER_PROBE))
    assert part is table and np.array_equal(rows, np.arange(len(table))) and entry.probe == PAPER_PROBE


def test_probes_named_by_id_need_the_column(table):
    with pytest.raises(TableError, match="no column 'probe'"):
        with_probes(table, ProbeSet.of({0: PAPER_PROBE, 1: PAPER_PROBE}))


def test_a_plugin_sees_each_rows_own_probe_never_the_set(table):
    """docs/model_lab.md: a plugin ``(rows, probe, …)`` gets its rows' probe's constants, also
    where the lab checks it can be evaluated (in a fit and among the candidates) and records
    the columns it reads."""
    other = dataclasses.replace(PAPER_PROBE, spring_nm_per_rad=PAPER_PROBE.spring_nm_per_rad * 1.072)
    two = table.with_columns(probe=np.arange(len(table)) % 2.0)
    probes = ProbeSet.of({0: PAPER_PROBE, 1: other})
    seen = []

    @effect(name="probe_check", parameters={"k": (0.0, -1.0, 1.0, "Hz")})
    def probe_check(rows, probe, k):
        seen.append((probe, set(rows.probe.tolist())))
        return {"frequency_hz": k * np.ones(len(rows))}

    fit = FrequencyModel(probes).fit(two)
    (fit.model + probe_check).fit(two)
    diagnose(fit, [probe_check], probes)  # ranks it as a candidate
    assert seen and all(type(probe) is Probe for probe, _ in seen)
    for probe, ids in seen:
        (member,) = ids
        assert probe == probes.members[int(member)].probe
    assert {member for _, ids in seen for member in ids} == {0.0, 1.0}


def test_each_probe_of_a_set_has_its_own_ring_down_amplitudes():
    """The amplitude's alias with a moment scale (``amplitude_scale_error``) takes each row's
    start swing from its own probe's housing stop. The truth is each probe's rows alone, a table
    of one probe: a probe stopped at half the swing weakens its field spring four times less."""
    other = dataclasses.replace(PAPER_PROBE, theta_stop_rad=PAPER_PROBE.theta_stop_rad / 2)
    alone = [_stopped_table(probe, seed) for seed, probe in enumerate((PAPER_PROBE, other))]
    columns = {name: np.concatenate([t.columns[name] for t in alone]) for name in alone[0].columns}
    columns["probe"] = np.repeat([0.0, 1.0], [len(t) for t in alone])
    epsilon, spread = amplitude_scale_error(MeasurementTable(columns), ProbeSet.of({0: PAPER_PROBE, 1: other}))
    each = [amplitude_scale_error(t, ProbeSet.one(probe))[0] for t, probe in zip(alone, (PAPER_PROBE, other))]
    assert each[1] == pytest.approx(each[0] / 4, rel=0.1)  # the premise: the stops tell the probes apart
    # Each row's fit window is 60 periods of the rows that ring alike, here both probes' (their
    # f00 is one): 1e-5 of it at most.
    assert epsilon == pytest.approx(np.average(each, weights=[len(t) for t in alone]), rel=1e-5)
    assert spread >= abs(each[0] - each[1])


def _stopped_table(probe, seed):
    """Ring-downs of ``probe`` in 20 µT, in a table that states no amplitude: the stop decides."""
    sweep = synthetic.rotation_sweeps(15.0, 2)
    theta0 = sweep.pop("theta0_deg")
    table = synthetic.synthesize(probe, UniformField((20e-6, 0.0, 0.0)), theta0, np.random.default_rng(seed), **sweep)
    return MeasurementTable({name: values for name, values in table.columns.items() if name != "amplitude_deg"})
