"""Discovery beyond the catalog (mows.lab.diagnosis.discovery): a term planted on an exact table is
found with its family and strength, its plugin writes it as physics and explains the table, and
tables without a hidden effect give no term.

The tables are exact physics (mows.lab.data.synthetic) in a 0.43 mT field at 2° ring-downs: four
sweeps of 24 orientations, the temperature scattered over 293–303 K (not the clock), the coil
current one step per sweep. The model fitted to them is the truth's physics: Eq. 6 with the
static deflection at physics (2° ring-downs make the finite amplitude negligible)."""

import math
import time

import numpy as np
import pytest

from mows.lab import FrequencyModel, ProbeSet, analyse, catalog, load_plugins
from mows.lab.data import synthetic
from mows.lab.diagnosis import discovery
from mows.lab.diagnosis.discovery import CHANNELS, discover
from mows.lab.diagnosis.discovery.channels import BY_NAME, FREQUENCY, jacobians
from mows.lab.diagnosis.discovery.library import factor_values, monomial_values
from mows.lab.diagnosis.discovery.plugin_source import writable
from mows.lab.diagnosis.discovery.readings import family, reading
from mows.lab.diagnosis.discovery.selection import RESAMPLES, STABLE_FRACTION
from mows.lab.report.html_report import discovery_html
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE

FIELD = UniformField((4e-4, 1.5e-4, -4e-5))
AMPLITUDE_DEG = 2.0
CURRENTS_A = (0.0, 1.0, 2.0, 3.0)
MOMENT_PER_K = -1e-3  # the planted moment's temperature coefficient
REFERENCE_K = PAPER_PROBE.reference_temperature_k  # where the probe's moment is m: the coefficient's zero
HEATING_HZ_PER_A2 = 2e-3  # the planted coil heating
CONTROL_SEEDS = 40


def rows(sweeps: int = 4) -> tuple[np.ndarray, dict]:
    sweep = synthetic.rotation_sweeps(15.0, sweeps)
    theta0 = sweep.pop("theta0_deg")
    temperature = 298.0 + np.random.default_rng(11).uniform(-5.0, 5.0, len(theta0))
    current = np.asarray(CURRENTS_A)[sweep["sweep"].astype(int) % len(CURRENTS_A)]
    return theta0, dict(sweep, temperature_k=temperature, coil_current_a=current)


@pytest.fixture(scope="module")
def exact():
    theta0, columns = rows()
    return theta0, columns, synthetic.true_frequency_hz(PAPER_PROBE, FIELD, np.radians(theta0), np.radians(2.0))


def table(exact, seed: int, hidden_hz=0.0):
    theta0, columns, truth = exact
    return synthetic.synthesize(
        PAPER_PROBE,
        FIELD,
        theta0,
        np.random.default_rng(seed),
        amplitude_deg=AMPLITUDE_DEG,
        truth_hz=truth + hidden_hz,
        **columns,
    )


def physical_fit(measured):
    return (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + catalog()["static_deflection"].at_physics()).fit(measured)


def moment_temperature_hz(measured):
    """A moment that changes by MOMENT_PER_K from the probe's reference temperature, to first order:
    β0·c·Bx'·(T − T_ref), Hz."""
    temperature = measured.temperature_k
    return PAPER_PROBE.beta0_hz_per_t * MOMENT_PER_K * measured.b_along_t * (temperature - REFERENCE_K)


def within(value, truth, std, sigmas=3.0):
    return abs(value - truth) <= sigmas * std


def test_a_moment_that_changes_with_temperature_is_found_as_field_times_temperature(exact, tmp_path):
    base = table(exact, 1)
    planted = moment_temperature_hz(base)
    measured = base.with_columns(f_hz=base.f_hz + planted)
    fit = physical_fit(measured)
    assert fit.chi2_dof > 5.0, fit.chi2_dof  # far above noise: no catalog effect of the model has it
    found = discover(fit, ProbeSet.one(PAPER_PROBE))
    assert [t.name for t in found.terms] == ["moment × temperature_k"], found.summary
    term = found.terms[0]
    assert term.channel == "moment" and term.family == "moment_temperature"
    assert term.strength_unit == "1/K"
    assert within(term.strength, MOMENT_PER_K, term.std), (term.strength, term.std, MOMENT_PER_K)
    # A reference sensor whose gain drifts with temperature scales the field's spring alike: listed,
    # with the measurement that tells the two apart.
    assert any(a.startswith("field_along × b_along_t·temperature_k") for a in term.alternatives), term.alternatives
    assert term.selection_frequency >= STABLE_FRACTION and term.cv_gain_chi2 > 0
    assert "temperature coefficient" in term.reading
    # What its strength is fitted to (the report's picture): the residual it explains against the
    # term beyond the model, whose weighted least-squares slope is the strength.
    shown = term.fitted
    weight = shown.std_hz**-2
    slope = np.sum(weight * shown.beyond_model * shown.residual_hz) / np.sum(weight * shown.beyond_model**2)
    assert slope == pytest.approx(term.strength, rel=1e-9)
    np.testing.assert_array_equal(shown.std_hz, measured.f_std_hz)
    assert "fitted" not in term.to_dict()
    # Its plugin is the moment changing with temperature, and reads the coefficient back.
    assert term.plugin_output == "moment_scale"
    assert within(term.plugin_parameter.value, MOMENT_PER_K, term.plugin_parameter.std)
    assert f"rows.temperature_k - {REFERENCE_K!r})" in term.plugin
    path = tmp_path / f"{term.effect_name}.py"
    path.write_text(term.plugin)
    (effect,) = load_plugins([path])
    (bounds,) = effect.parameters
    assert bounds.lower < -3 * abs(term.plugin_parameter.value) and 3 * abs(term.plugin_parameter.value) < bounds.upper
    with_plugin = (fit.model + effect).fit(measured)
    assert with_plugin.chi2_dof <= 1.5, with_plugin.chi2_dof
    (fitted,) = with_plugin.effect_parameters(effect.name)
    assert within(fitted.value, MOMENT_PER_K, fitted.std), fitted
    assert bounds.lower < fitted.value < bounds.upper


def test_coil_heating_is_found_as_current_squared_and_written_as_the_spring(exact, tmp_path):
    base = table(exact, 2)
    measured = base.with_columns(f_hz=base.f_hz + HEATING_HZ_PER_A2 * base.coil_current_a**2)
    fit = physical_fit(measured)
    found = discover(fit, ProbeSet.one(PAPER_PROBE))
    assert [t.name for t in found.terms] == ["spring × coil_current_a²"], found.summary
    term = found.terms[0]
    assert term.family == "spring_current_squared" and term.factors == ("coil_current_a", "coil_current_a")
    # Δk = 2·kM·Δf/f00 of a spring heated by I².
    spring = 2.0 * PAPER_PROBE.spring_nm_per_rad * HEATING_HZ_PER_A2 / PAPER_PROBE.f00_hz
    assert within(term.strength, spring, term.std), (term.strength, term.std)
    assert term.plugin_output == "stiffness_nm_per_rad"
    assert within(term.plugin_parameter.value, spring, term.plugin_parameter.std), term.plugin_parameter
    path = tmp_path / f"{term.effect_name}.py"
    path.write_text(term.plugin)
    (effect,) = load_plugins([path])
    with_plugin = (fit.model + effect).fit(measured)
    assert with_plugin.chi2_dof <= 1.5
    (fitted,) = with_plugin.effect_parameters(effect.name)
    assert within(fitted.value, spring, fitted.std), fitted


def test_tables_without_a_hidden_effect_give_no_term(exact):
    """The false-alarm bound: at most one of 40 noise seeds reports any term (measured: none)."""
    alarms = {}
    for seed in range(CONTROL_SEEDS):
        found = discover(physical_fit(table(exact, 100 + seed)), ProbeSet.one(PAPER_PROBE))
        if found.terms:
            alarms[seed] = [t.name for t in found.terms]
    assert len(alarms) <= 1, alarms


def test_a_long_table_is_searched_in_seconds():
    """1008 rows, the moment's temperature term at a third of its size above: found, and the
    search costs ~0.3 s of CPU (the bound leaves room for a loaded machine)."""
    theta0, columns = rows(sweeps=42)
    truth = synthetic.true_frequency_hz(PAPER_PROBE, FIELD, np.radians(theta0), np.radians(AMPLITUDE_DEG))
    base = table((theta0, columns, truth), 3)
    measured = base.with_columns(f_hz=base.f_hz + moment_temperature_hz(base) / 3.0)
    fit = physical_fit(measured)
    start = time.process_time()
    found = discover(fit, ProbeSet.one(PAPER_PROBE))
    assert time.process_time() - start < 5.0
    assert [t.name for t in found.terms] == ["moment × temperature_k"], found.summary
    term = found.terms[0]
    assert within(term.strength, MOMENT_PER_K / 3.0, term.std)


@pytest.mark.parametrize(
    ("channel", "factors"),
    [
        (c.name, factors)
        for c in CHANNELS
        if writable(c)
        for factors in [(), ("temperature_k",), ("coil_current_a", "coil_current_a")]
        if factors or c is not FREQUENCY  # the frequency has no constant term: f00 is one
    ],
)
def test_every_channel_writes_a_plugin_whose_signature_is_the_term(exact, tmp_path, channel, factors):
    """Every channel times a monomial: its reading is physics in words, and its plugin loads with
    load_plugins and changes the frequency as the channel's Jacobian times the monomial (the
    term the search fits), row by row: the written plugin is the term found."""
    measured = table(exact, 4)
    # A gradient, so that the magnet's position acts (through l·m·Gx'x' and the deflection's geometry).
    measured = measured.with_columns(
        ref_gxx_t_per_m=np.full(len(measured), 1e-2), ref_gxy_t_per_m=np.full(len(measured), 5e-3)
    )
    fit = physical_fit(measured)
    chosen = BY_NAME[channel]
    assert reading(chosen, factors) and family(chosen, factors).startswith(channel)
    means = {"temperature_k": REFERENCE_K}
    values = monomial_values(factor_values(measured, ProbeSet.one(PAPER_PROBE)), factors, len(measured))
    # A bound whose finite-difference step (1e-3 of the range) moves the channel as little as the
    # Jacobian's own step: the frequency is linear in the channel there.
    bound = 1e3 * chosen.step / np.abs(values).max()
    plugin = discovery.Plugin(chosen, factors, means, bound, ProbeSet.one(PAPER_PROBE), reading(chosen, factors))
    path = tmp_path / f"{plugin.name}.py"
    path.write_text(plugin.source())
    (effect,) = load_plugins([path])
    assert effect.name == plugin.name and effect.parameters[0].upper == bound
    signature = -fit.extension_columns(effect)[:, 0]
    weight = 1.0 / measured.f_std_hz
    term = (weight * values) if chosen is FREQUENCY else jacobians(fit, measured, weight)[channel] * values
    assert np.ptp(signature) > 0
    np.testing.assert_allclose(signature, term, rtol=1e-3, atol=1e-4 * np.abs(term).max())


def test_the_verdict_and_the_report_carry_the_discovery(exact):
    """A table the catalog cannot explain: the verdict's hint is the discovered term's physical
    plugin, and the report's JSON, text and HTML show the discovery."""
    from mows.cli.lab_text import format_text

    base = table(exact, 5)
    measured = base.with_columns(f_hz=base.f_hz + moment_temperature_hz(base))
    report = analyse(
        measured, ProbeSet.one(PAPER_PROBE), effects=["static_deflection (at physics)"], cross_validate=False
    )
    assert report.verdict == "unexplained_structure", report.diagnosis.explanation
    explanation = report.diagnosis.explanation
    assert "finds 1 term: moment × temperature_k" in explanation, explanation
    assert "--plugin discovered_moment_temperature_k.py" in explanation
    assert f'"moment_scale": c * (rows.temperature_k - {REFERENCE_K!r})' in explanation
    found = report.to_dict()["discovery"]
    assert found["terms"][0]["family"] == "moment_temperature"
    assert found["library"] > 0 and found["resamples"] == RESAMPLES and found["degree"] == 2
    assert (
        "plugin for the strongest, in its channel (moment), to save as discovered_moment_temperature_k.py"
        in format_text(report, measured, "diagnose")
    )
    assert "<h2>Beyond the catalog</h2>" in discovery_html(report)


def test_a_generic_correction_is_searched_without_it(exact):
    """A moment 1 % stronger than the probe file's: --auto explains it with the generic moment
    scale (needs_generic_term), and the discovery on the model without it names the field's
    spring scaled, with the moment-scale plugin at +1 %."""
    theta0, columns, _ = exact
    stronger = PAPER_PROBE.replace(moment_am2=PAPER_PROBE.moment_am2 * 1.01)
    truth = synthetic.true_frequency_hz(stronger, FIELD, np.radians(theta0), np.radians(AMPLITUDE_DEG))
    measured = table((theta0, columns, truth), 6)
    report = analyse(measured, ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert report.verdict == "needs_generic_term", report.history
    assert report.discovery is not None and "moment_scale" not in report.discovery.on_model
    term = report.discovery.terms[0]
    assert term.name == "moment × 1" and term.plugin_output == "moment_scale", report.discovery.summary
    assert within(term.plugin_parameter.value, 0.01, term.plugin_parameter.std, sigmas=5.0), term.plugin_parameter
    assert not math.isnan(term.cv_gain_chi2) and term.cv_gain_chi2 > 0
