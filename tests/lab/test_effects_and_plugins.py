"""Composition, plugins (files and their errors) and the fit's bookkeeping."""

import dataclasses
import math
import textwrap

import numpy as np
import pytest

from mows.lab import FrequencyModel, ProbeSet, analyse, catalog, load_plugins
from mows.lab.data import synthetic
from mows.physics.field import UniformField
from mows.physics.probe import PAPER_PROBE

PLUGIN = textwrap.dedent("""
    from mows.lab import effect

    @effect(name="coil_heating", parameters={"k_per_a2_nm_per_rad": (0.0, -1e-9, 1e-9, "N·m/rad/A²")},
            explanation="the coil warms the spring: Δk ∝ I²", signature="grows with coil current squared")
    def coil_heating(rows, k_per_a2_nm_per_rad):
        return {"stiffness_nm_per_rad": k_per_a2_nm_per_rad * rows.coil_current_a ** 2}
""")


def test_models_compose_with_plus():
    effects = catalog()
    model = FrequencyModel(ProbeSet.one(PAPER_PROBE)) + effects["gravity"] + effects["thermal_drift"]
    assert model.parameter_names == [
        "f00_hz",
        "gravity.down_x",
        "gravity.down_y",
        "thermal_drift.spring_temp_coeff_per_k",
    ]
    pair = FrequencyModel() + effects["gravity"] + effects["field_offset"]
    assert pair.effect_names == ["gravity", "field_offset"] and pair.probe is None
    assert (effects["gravity"] + FrequencyModel(ProbeSet.one(PAPER_PROBE))).effect_names == ["gravity"]
    assert (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + pair).parameter_names == [
        "f00_hz",
        "gravity.down_x",
        "gravity.down_y",
        "field_offset.bx_t",
        "field_offset.by_t",
    ]
    with pytest.raises(ValueError, match="more than once"):
        model + effects["gravity"]


def test_a_plugin_file_defines_an_effect_that_the_lab_finds(tmp_path):
    path = tmp_path / "my_effect.py"
    path.write_text(PLUGIN)
    (plugin,) = load_plugins([str(path)])
    assert plugin.name == "coil_heating"
    # Truth from exact physics with a spring that really follows I² (the probe's kM per row).
    rng = np.random.default_rng(0)
    sweep = synthetic.rotation_sweeps(15.0, 4)
    current = np.repeat([0.0, 2.0, 4.0, 6.0], 24)
    truth = np.array(
        [
            synthetic.true_frequency_hz(
                PAPER_PROBE.replace(spring_nm_per_rad=PAPER_PROBE.spring_nm_per_rad + 3e-10 * i**2),
                UniformField((2e-5, 1e-5, 0)),
                [np.radians(t)],
                np.radians(2.0),
            )[0]
            for i, t in zip(current, sweep["theta0_deg"])
        ]
    )
    theta0 = sweep.pop("theta0_deg")
    table = synthetic.synthesize(
        PAPER_PROBE,
        UniformField((2e-5, 1e-5, 0)),
        theta0,
        rng,
        truth_hz=truth,
        amplitude_deg=2.0,
        coil_current_a=current,
        **sweep,
    )
    report = analyse(table, ProbeSet.one(PAPER_PROBE), auto=True, plugins=[str(path)], cross_validate=False)
    assert report.verdict == "adequate"
    assert "coil_heating" in report.effects
    value = {p.name: (p.value, p.std) for p in report.fit.parameters()}["coil_heating.k_per_a2_nm_per_rad"]
    assert abs(value[0] - 3e-10) < 2 * value[1]


@pytest.mark.parametrize(
    "text, words",
    [
        ("x = 1\n", ["defines no effect"]),
        ("raise RuntimeError('boom')\n", ["failed to load", "boom"]),
        (
            "from mows.lab import effect\n@effect(name='e', parameters={'a': (3.0, -1, 2, '1')})\ndef e(rows, a):\n"
            "    return {}\n",
            ["lower ≤ off value ≤ upper"],
        ),
    ],
)
def test_broken_plugins_say_what_is_wrong(tmp_path, text, words):
    path = tmp_path / "bad.py"
    path.write_text(text)
    with pytest.raises(ValueError) as error:
        load_plugins([str(path)])
    for word in words:
        assert word in str(error.value)


def test_an_existing_file_that_is_not_python_is_a_clear_error(tmp_path):
    path = tmp_path / "effects.txt"  # exists, so taken as a plugin file, but Python cannot import it
    path.write_text("x = 1\n")
    with pytest.raises(ValueError, match="not a Python file"):
        load_plugins([str(path)])


def test_unknown_plugins_and_effects_are_named():
    with pytest.raises(ValueError, match="no_such_plugin"):
        load_plugins(["no_such_plugin"])
    with pytest.raises(ValueError, match="gravit"):
        analyse(
            {"theta0_deg": [0, 90], "f_hz": [112.5, 112.5], "f_std_hz": [1e-3, 1e-3]},
            ProbeSet.one(PAPER_PROBE),
            effects=["gravit"],
        )


def test_the_same_table_under_two_probes_gives_each_probes_own_prediction():
    """A table without amplitude or damping columns takes them from the probe, so a cached
    ring-down average must not carry one probe's stop over to the other."""
    table = synthetic.synthesize(
        PAPER_PROBE, UniformField((2e-4, 1e-4, 0.0)), np.arange(0.0, 360.0, 60.0), np.random.default_rng(1)
    )
    bare = type(table)(
        {k: v for k, v in table.columns.items() if k not in ("amplitude_deg", "damping_per_s", "duration_s")}
    )
    narrow = dataclasses.replace(PAPER_PROBE, theta_stop_rad=math.radians(5.0))
    effect = catalog()["finite_amplitude"].at_physics()
    for probe in (PAPER_PROBE, narrow):
        model = FrequencyModel(ProbeSet.one(probe)) + effect
        shared = model.predict(bare, [probe.f00_hz])
        fresh = model.predict(bare.with_columns(), [probe.f00_hz])
        np.testing.assert_allclose(shared, fresh, rtol=0, atol=1e-9)
    wide, small = ((FrequencyModel(ProbeSet.one(p)) + effect).predict(bare, [p.f00_hz]) for p in (PAPER_PROBE, narrow))
    assert np.max(np.abs(wide - small)) > 1e-3  # the stop matters here: the test can tell them apart
