"""Effects at their physical value, the stepwise selection that revisits its choices, and the
live demo's anti-Helmholtz sweep, on which greedy forward selection diagnoses curvature."""

import json
import pathlib

import numpy as np
import pytest

from lab.tables import rotation_table
from mows.cli.main import main
from mows.lab import FrequencyModel, ProbeSet, analyse, catalog, load_table
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE
from mows.sim.scenario import load_scenario

DEMO = pathlib.Path(__file__).parent / "data" / "demo_sweep.csv"
EARTH = UniformField((15e-6, -12e-6, -40e-6))


def test_an_effect_at_physics_is_the_free_effect_at_its_physical_value():
    table = load_table(DEMO)
    effects = catalog()
    for name in ("transverse_gradient", "static_deflection", "finite_amplitude", "damping_shift"):
        fixed = effects[name].at_physics()
        assert fixed.parameters == () and fixed.label == f"{name} (at physics)" and fixed.free is effects[name]
        np.testing.assert_array_equal(
            (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + fixed).predict(table, [112.48]),
            (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effects[name]).predict(table, [112.48, 1.0]),
        )
    with pytest.raises(ValueError, match="tilt|known"):
        effects["gravity"].at_physics()


def test_the_demo_sweep_is_known_physics_not_curvature():
    """8 orientations × 2 ring-downs in the anti-Helmholtz scenario, from the 24° stop. The full
    physics at the reference (everything at strength 1, only f00 free) fits with χ²/dof 0.82;
    greedy selection with free strengths adds transverse_gradient (0.92) and field_curvature.
    A strength of 0.92 ± 0.004 is 7 σ from physics (1 ± 1 %): the lab never takes it, and says
    what it would need."""
    probe = load_scenario("anti_helmholtz").probe
    table = load_table(DEMO)
    physics = [
        catalog()[name].at_physics() for name in ("transverse_gradient", "finite_amplitude", "static_deflection")
    ]
    assert FrequencyModel(ProbeSet.one(probe), physics).fit(table).chi2_dof < 1.0
    report = analyse(table, ProbeSet.one(probe), auto=True, cross_validate=False)
    assert "field_curvature" not in report.effect_names, report.history
    assert {"transverse_gradient (at physics)", "finite_amplitude (at physics)"} <= set(report.effects)
    assert report.history[1].effects == ["transverse_gradient (at physics)"]
    assert "field_curvature" not in {name for step in report.history for name in step.effects}
    first = analyse(table, ProbeSet.one(probe), cross_validate=False)
    transverse = next(c for c in first.candidates if c.name == "transverse_gradient")
    assert transverse.form == "at physics"
    assert transverse.free.conflicts[0].parameter == "transverse_gradient.strength"
    assert transverse.free.conflicts[0].sigmas > 5.0, transverse.free.conflicts
    for check in report.physics_checks:
        assert not check.held or check.deviation_sigma < 3.0, check


def strong_field_table(truth_amplitude_deg, seed=0):
    """A 170 µT field along x (Helmholtz-like) plus Earth's, ring-downs at 24° according to the
    table; the truth has the amplitude ``truth_amplitude_deg``."""
    source = UniformField((170e-6, 0.0, 0.0)) + EARTH
    return rotation_table(source, seed, truth_amplitude_deg, f_std_hz=4e-4, amplitude_deg=24.0)


def test_known_physics_is_added_at_physics_when_the_data_have_it():
    report = analyse(strong_field_table(24.0), ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert {"finite_amplitude (at physics)", "static_deflection (at physics)"} <= set(report.effects), report.history
    assert report.verdict == "adequate"
    value, std = report.effect_parameter("finite_amplitude.strength")  # the free fit, as a check
    assert abs(value - 1.0) < 3 * std


def test_known_physics_the_data_do_not_have_is_rejected():
    # The table says 24°, the truth swung 1°: the amplitude effect predicted at physics is absent.
    report = analyse(strong_field_table(1.0), ProbeSet.one(PAPER_PROBE), auto=True, cross_validate=False)
    assert "finite_amplitude" not in report.effect_names, report.history
    first = analyse(strong_field_table(1.0), ProbeSet.one(PAPER_PROBE), cross_validate=False)
    amplitude = next(c for c in first.candidates if c.name == "finite_amplitude")
    assert amplitude.physics.signal_chi2 > 100  # it would be seen …
    assert amplitude.physics.delta_bic < -100 and amplitude.physics.p_value > 1e-3  # … and is not there
    assert abs(amplitude.parameters[0].value) < 3 * amplitude.parameters[0].std  # free: strength ≈ 0


def test_json_and_command_line_carry_the_form(tmp_path, capsys):
    assert main(["lab", "add", str(DEMO), "transverse_gradient (at physics)", "--json", "--no-cv"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["effects"] == ["transverse_gradient (at physics)"]
    assert [step["change"] for step in result["history"]] == ["base model", "add transverse_gradient (at physics)"]
    assert result["physics_checks"][0]["effect"] == "transverse_gradient"
    candidate = next(c for c in result["candidates"] if c["effect"] == "finite_amplitude")
    assert candidate["form"] in ("free", "at physics") and set(candidate["at_physics"]) >= {"delta_bic", "p_value"}
    assert set(candidate["parameters"]) == {"strength"}
    assert main(["lab", "add", str(DEMO), "--auto", "--no-cv"]) == 0
    out = capsys.readouterr().out
    assert "at physics" in out and "their free fit" in out and "add transverse_gradient (at physics)" in out
