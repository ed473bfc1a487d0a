"""A hidden effect outside the catalog, found as the hint says and modelled by a plugin as physics.

Requirement: the magnet's moment falls with temperature (NdFeB, −1e-3/K here) during a warming
run. No catalog effect is that: the lab must end without catalog effects that are not there
(those of the truth are the static deflection and, at 2° ring-downs, a negligible finite
amplitude and damping term), say ``unexplained_structure``, point at temperature × Bx' with a
plugin in the physical form (a moment scale, its coefficient read from the table by the search
beyond the catalog), and the user's plugin written as physics
(``moment_scale`` through the full potential) must explain the table to χ²/dof ≤ 1.5 and read
the coefficient back. The truth is the exact arc energy of a probe whose moment is changed row
by row (:func:`mows.lab.data.synthetic.true_frequency_hz`), independent of the lab's
configuration.
"""

import numpy as np
import pytest

from mows.lab import FrequencyModel, ProbeSet, analyse, catalog
from mows.lab.data import synthetic
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE

MOMENT_PER_K = -1e-3
REFERENCE_K = PAPER_PROBE.reference_temperature_k  # where the probe file's moment holds
AMPLITUDE_DEG = 2.0
FIELD_T = (4e-4, 1.5e-4, -4e-5)
PLUGIN = f"""
from mows.lab import effect


@effect(name="moment_temperature", parameters={{"c_per_k": (0.0, -1e-2, 1e-2, "1/K")}},
        explanation="the magnet's moment changes with temperature: m(T) = m·(1 + c·(T − {REFERENCE_K}))")
def moment_temperature(rows, c_per_k):
    return {{"moment_scale": c_per_k * (rows.temperature_k - {REFERENCE_K})}}
"""
PHYSICAL_KEEP = {"static_deflection", "finite_amplitude", "damping_shift"}  # what the truth holds


@pytest.fixture(scope="module")
def table():
    """Four sweeps every 15° while the probe warms 10 K (with 0.5 K of scatter, so that the
    temperature is not the clock); noise 1 mHz."""
    sweep = synthetic.rotation_sweeps(15.0, 4)
    theta0 = sweep.pop("theta0_deg")
    rng = np.random.default_rng(4)
    temperature = 293.0 + 10.0 * sweep["t_s"] / np.ptp(sweep["t_s"]) + rng.uniform(-0.5, 0.5, len(theta0))
    source = UniformField(FIELD_T)
    # The moment follows the temperature; the spring is held (no thermal drift in this truth).
    magnet = PAPER_PROBE.replace(moment_temp_coeff_per_k=MOMENT_PER_K, spring_temp_coeff_per_k=0.0)
    truth = synthetic.true_frequency_hz(magnet, source, np.radians(theta0), np.radians(AMPLITUDE_DEG), temperature)
    return synthetic.synthesize(
        PAPER_PROBE,
        source,
        theta0,
        rng,
        amplitude_deg=AMPLITUDE_DEG,
        truth_hz=truth,
        temperature_k=temperature,
        **sweep,
    )


@pytest.mark.slow  # an --auto selection on 96 rows
def test_the_catalog_alone_adds_only_what_is_there_and_points_at_the_moment(table):
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert report.base.chi2_dof > 20.0, report.base.chi2_dof  # the hidden effect is far above noise
    assert set(report.effect_names) <= PHYSICAL_KEEP, report.history
    assert report.verdict == "unexplained_structure", report.diagnosis.explanation
    explanation = report.diagnosis.explanation
    assert "temperature_k·b_along_t" in explanation, explanation
    # The search beyond the catalog writes the moment's plugin and reads its coefficient from the table.
    assert "finds 1 term: moment × temperature_k" in explanation, explanation
    assert f'"moment_scale": c * (rows.temperature_k - {REFERENCE_K!r})' in explanation, explanation
    (term,) = report.discovery.terms
    assert abs(term.plugin_parameter.value - MOMENT_PER_K) < 3 * term.plugin_parameter.std, term.plugin_parameter


@pytest.mark.slow  # an --auto selection on 96 rows
def test_the_users_physical_plugin_explains_the_table_and_reads_the_coefficient(table, tmp_path):
    path = tmp_path / "moment_temperature.py"
    path.write_text(PLUGIN)
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, plugins=[str(path)], cross_validate=False)
    assert "moment_temperature" in report.effect_names, report.history
    assert report.fit.chi2_dof <= 1.5, report.history
    value, std = report.effect_parameter("moment_temperature.c_per_k")
    assert abs(value - MOMENT_PER_K) < 3 * std + 2e-5, (value, std)
    assert set(report.effect_names) - {"moment_temperature"} <= PHYSICAL_KEEP, report.history


FIELD_PLUGIN = """
from mows.lab import effect


@effect(name="unseen_field", parameters={"by_t": (0.0, -1e-3, 1e-3, "T")})
def unseen_field(rows, by_t):
    return {"field_offset_t": (0.0, by_t)}
"""


def test_a_plugins_field_goes_through_the_potential(tmp_path):
    """A 60 µT field along y that the reference does not see, at 24° ring-downs: the plugin's
    in-plane field offset, through the full potential (deflection and amplitude springs at
    physics), explains the table and reads the field back. The truth is the exact arc energy
    in the whole field; the table's reference is the seen part."""
    sweep = synthetic.rotation_sweeps(15.0, 2)
    theta0 = sweep.pop("theta0_deg")
    seen = UniformField(FIELD_T)
    whole = UniformField((FIELD_T[0], FIELD_T[1] + 6e-5, FIELD_T[2]))
    table = synthetic.synthesize(PAPER_PROBE, whole, theta0, np.random.default_rng(5), reference=seen, **sweep)
    path = tmp_path / "unseen_field.py"
    path.write_text(FIELD_PLUGIN)
    effects = catalog([str(path)])
    model = FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effects["static_deflection"].at_physics()
    model = model + effects["finite_amplitude"].at_physics() + effects["unseen_field"]
    fit = model.fit(table)
    assert fit.chi2_dof <= 1.5, fit.chi2_dof
    (field,) = fit.effect_parameters("unseen_field")
    assert abs(field.value - 6e-5) < 3 * field.std, field
