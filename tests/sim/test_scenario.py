"""Scenario YAML: shipped files, round trips, the documented examples and the error messages."""

import json
import math
import pathlib
import re

import numpy as np
import pytest
import yaml

from mows.physics.coupling import PlacedProbe
from mows.physics.probe import PAPER_PROBE
from mows.sim.scenario import SCENARIO_DIR, Scenario, load_scenario, shipped_scenarios
from mows.sim.scenario_yaml import pose_to_dict

DOC = pathlib.Path(__file__).parents[2] / "docs" / "scenario_format.md"
SETUPS = {
    "paper_largest_spacing": "largest_spacing",
    "helmholtz": "helmholtz",
    "anti_helmholtz": "helmholtz",
    "nearby_coil": "largest_spacing",
    "tilted_plane": "largest_spacing",
    "calibration": "helmholtz",
    "calibration_gradient": "helmholtz",
    "three_probes": "helmholtz",
}


def test_the_shipped_scenarios_are_the_documented_ones():
    assert shipped_scenarios() == sorted(SETUPS)


@pytest.mark.parametrize("name", sorted(SETUPS))
def test_shipped_scenario_round_trips(name, tmp_path):
    scenario = load_scenario(name)
    assert scenario.name == name and scenario.setup.name == SETUPS[name]
    again = Scenario.from_dict(scenario.to_dict())
    assert again.to_dict() == scenario.to_dict()
    scenario.to_yaml(tmp_path / "s.yaml")
    assert load_scenario(tmp_path / "s.yaml").to_dict() == scenario.to_dict()


def test_the_default_is_the_paper_device_in_the_largest_spacing_setup_in_the_earths_field():
    scenario = load_scenario()
    assert scenario.name == "paper_largest_spacing" and scenario.probe == PAPER_PROBE
    earth = scenario.environment.source.field_t(np.zeros(3))
    assert np.linalg.norm(earth) == pytest.approx(48e-6, rel=0.01)
    assert np.hypot(*earth[:2]) > 10e-6 and earth[2] < -30e-6  # horizontal and vertical parts
    assert scenario.sample_rate_hz == 20_000.0 and scenario.sensors.null_offsets
    assert scenario.excitation.frequency_hz is None


def test_a_scene_of_three_probes_places_each_with_its_own_constants():
    scenario = load_scenario("three_probes")
    placed = scenario.placed_probes()
    assert [round(p.probe.f00_hz, 9) for p in placed] == [100.0, 112.5, 125.0]
    positions = np.array([p.pose.magnet_position_m for p in placed])
    distances = [np.linalg.norm(positions[i] - positions[j]) for i, j in ((0, 1), (0, 2), (1, 2))]
    assert all(0.04 <= d <= 0.06 for d in distances)
    assert {p.stage for p in scenario.probes} == {"shared"}
    # The first probe is the scene's probe: the coil preset and the sensors sit around it.
    assert scenario.probe == placed[0].probe and scenario.pose == placed[0].pose
    turned = scenario.placed_probes([0.1, 0.2, 0.3])
    assert [p.pose.theta0_rad for p in turned] == [0.1, 0.2, 0.3]
    assert turned[2].pose.magnet_position_m == placed[2].pose.magnet_position_m


def test_a_single_probe_scene_is_a_group_of_one():
    scenario = load_scenario("anti_helmholtz")
    assert len(scenario.probes) == 1 and scenario.probes[0].stage == "own"
    assert scenario.placed_probes() == [PlacedProbe(scenario.probe, scenario.pose)]
    # Written in the one shape, it reads back as the same group of one.
    written = scenario.to_dict()
    assert "probe" not in written and "pose" not in written and len(written["probes"]) == 1
    again = Scenario.from_dict(written)
    assert again.probes == scenario.probes and again.to_dict() == written


def test_the_older_shape_and_a_list_of_one_are_the_same_scene():
    pose = {"magnet_position_m": [0.01, 0.0, 0.0], "theta0_deg": 30.0}
    older = Scenario.from_dict({"probe": "paper", "pose": pose})
    listed = Scenario.from_dict({"probes": [{"probe": "paper", "pose": pose}]})
    assert older.probes == listed.probes and older.to_dict() == listed.to_dict()
    # The stage turns each probe from its home orientation, the probe of one as those of several.
    assert older.stage_orientations_rad(0.5) == pytest.approx([math.radians(30.0) + 0.5])


@pytest.mark.parametrize(
    "change, message",
    [
        ({"pose": {"theta0_deg": 10.0}}, "either probe and pose"),
        ({"probes": []}, "list of 1 to 4 probes"),
        (
            {"probes": [{"pose": {"magnet_position_m": [0.0, 0.0, 0.0]}}] * 2},
            "probes[1].pose.magnet_position_m = [0.0, 0.0, 0.0] is 0.00 mm from probes[0].pose.magnet_position_m",
        ),
        ({"probes": [{"stage": "turntable"}]}, "probes[0].stage = 'turntable'"),
        ({"probes": [{"colour": "red"}]}, "probes[0]: unknown keys ['colour']"),
        ({"probes": [{"pose": {"theta0_deg": "east"}}]}, "probes[0].pose.theta0_deg = 'east' is not a number"),
        (
            {"probes": [{"probe": {**PAPER_PROBE.to_dict(), "moment_am2": -1.0}}]},
            "probes[0].probe.moment_am2 = -1.0 is out of range",
        ),
    ],
)
def test_bad_probe_lists_are_refused_by_name(change, message):
    scene = {"name": "x", "probes": [{"pose": {"magnet_position_m": [0.0, 0.0, 0.0]}}], **change}
    with pytest.raises(ValueError, match=re.escape(message)):
        Scenario.from_dict(scene)


def yaml_blocks(text):
    return [yaml.safe_load(block) for block in re.findall(r"```yaml\n(.*?)```", text, flags=re.S)]


def test_the_documented_examples_are_the_shipped_files():
    blocks = yaml_blocks(DOC.read_text())
    named = {b["name"]: b for b in blocks if b.get("name") in SETUPS}
    assert set(named) == {"paper_largest_spacing", "helmholtz", "anti_helmholtz", "nearby_coil"}
    for name, block in named.items():
        assert Scenario.from_dict(block).to_dict() == load_scenario(name).to_dict(), name
    base = yaml.safe_load((SCENARIO_DIR / "base.yaml").read_text())
    assert base in blocks
    no_hum = Scenario.from_dict(next(b for b in blocks if b.get("name") == "helmholtz_no_hum"))
    assert no_hum.noise.mains_t == 0.0 and no_hum.setup.name == "helmholtz"
    minimal = Scenario.from_dict(next(b for b in blocks if b.get("name") == "one_millitesla"))
    np.testing.assert_array_equal(minimal.environment.source.field_t(np.zeros(3)), [1e-3, 0.0, 0.0])


def test_defaults_and_derived_sections():
    scenario = Scenario.from_dict({"pose": {"magnet_position_m": [0.01, 0.02, 0.0], "theta0_deg": 90.0}})
    assert scenario.pose.theta0_rad == pytest.approx(math.pi / 2)
    # The sensors follow the magnet: the paper's pair at 6 cm and r_eff = 6.75 cm along +x.
    np.testing.assert_allclose(scenario.sensors.pair.positions_m[0], [0.07, 0.02, 0.0])
    # So do the preset coils: their field at the magnet is what it is at the origin without the move.
    at_origin = Scenario.from_dict({}).setup.coil_field_per_ampere_t(np.zeros(3))
    np.testing.assert_allclose(scenario.setup.coil_field_per_ampere_t([0.01, 0.02, 0.0]), at_origin, rtol=1e-12)
    tilted = Scenario.from_dict({"pose": {"tilt_deg": 30.0}})
    assert tilted.pose.gravity_m_per_s2[1] == pytest.approx(9.80665 / 2)


def test_probe_forms(tmp_path):
    inline = PAPER_PROBE.replace(damping_per_s=0.5).to_dict()
    inline.pop("f00_hz")
    assert Scenario.from_dict({"probe": inline}).probe.damping_per_s == 0.5
    PAPER_PROBE.to_yaml(tmp_path / "probe.yaml")
    (tmp_path / "s.yaml").write_text("probe: probe.yaml\n")
    assert load_scenario(tmp_path / "s.yaml").probe.to_dict() == PAPER_PROBE.to_dict()


@pytest.mark.parametrize(
    "data, message",
    [
        ({"colour": 1}, r"unknown keys \['colour'\].*allowed keys are \['name'"),
        ({"noise": {"white": 1e-11}}, r"^noise: unknown keys \['white'\].*sensor_white_t_per_rthz"),
        ({"pose": {"theta0_rad": 1.0}}, r"^pose: unknown keys \['theta0_rad'\].*theta0_deg"),
        ({"pose": {"tilt_deg": 10.0, "gravity_m_per_s2": [0, 0, -9.8]}}, "either tilt_deg"),
        ({"pose": {"theta0_deg": "north"}}, r"^pose.theta0_deg = 'north' is not a number"),
        ({"excitation": {"amplitude_a": 12.0}}, "exceeds the cap of 10 A"),
        ({"excitation": {"ringdown_s": 0.0}}, r"^excitation.ringdown_s = 0.0 is out of range \(0, 3600\]"),
        ({"sample_rate_hz": -1.0}, r"sample_rate_hz = -1.0 is out of range"),
        ({"housing": {"restitution": 1.5}}, r"^housing.restitution = 1.5 is out of range \(0, 1\]"),
        ({"integrator": {"substeps": 0}}, r"^integrator.substeps = 0 must be an integer in \[1, 1000\]"),
        (
            {"sensors": {"positions_m": [[0.06, 0, 0]]}},
            r"^sensors.positions_m = \[\[0.06, 0, 0\]\] must be two 3-vectors",
        ),
        ({"probe": "no_such_probe.yaml"}, "^probe = 'no_such_probe.yaml' is neither 'paper' nor a probe file"),
        (
            {"environment": {"sources": [{"type": "magnet"}]}},
            r"^environment.sources\[0\]: .*field source type 'magnet'",
        ),
        ({"setup": {"preset": "triangle"}}, "^setup: .*coil preset 'triangle'"),
        ({"pose": {"plane_e1": [1, 0, 0], "plane_e2": [0, 0, 1]}}, r"not x–y .* setup \(a coil preset\) and sensors"),
    ],
)
def test_bad_scenarios_are_refused_with_a_message_naming_the_key(data, message):
    with pytest.raises(ValueError, match=message):
        Scenario.from_dict(data)


def test_unknown_scenario_name_lists_the_shipped_ones():
    with pytest.raises(ValueError, match="paper_largest_spacing"):
        load_scenario("no_such_scenario")


SHIPPED_BEFORE_EXTENDS = pathlib.Path(__file__).with_name("data") / "shipped_scenarios.json"


@pytest.mark.parametrize("name", sorted(set(SETUPS) - {"three_probes"}))
def test_shipped_scenarios_load_as_they_did_when_every_file_was_written_out_in_full(name):
    """data/shipped_scenarios.json is ``to_dict()`` of each shipped scene captured from the
    files as they were before they shared a base (``extends``), in the older shape of one probe
    (``probe`` and ``pose``), which reads as a group of one; JSON keeps floats exactly."""
    before = json.loads(SHIPPED_BEFORE_EXTENDS.read_text())[name]
    assert "probe" in before and "probes" not in before
    assert json.loads(json.dumps(load_scenario(name).to_dict())) == Scenario.from_dict(before).to_dict()
    probe_and_pose = load_scenario(name).probes[0]
    assert (probe_and_pose.probe.to_dict(), pose_to_dict(probe_and_pose.pose)) == (before["probe"], before["pose"])


def test_extends_merges_mappings_key_by_key_and_replaces_lists(tmp_path):
    (tmp_path / "quiet.yaml").write_text(
        "extends: helmholtz\nname: quiet\nnoise: {mains_t: 0.0}\nenvironment: {sources: [], temperature_k: 300.0}\n"
    )
    quiet, helmholtz = load_scenario(tmp_path / "quiet.yaml"), load_scenario("helmholtz")
    assert quiet.name == "quiet" and quiet.setup.name == "helmholtz"
    assert quiet.noise.mains_t == 0.0
    assert quiet.noise.sensor_white_t_per_rthz == helmholtz.noise.sensor_white_t_per_rthz == 1e-11
    assert quiet.environment.sources == () and quiet.environment.temperature_k == 300.0
    assert quiet.to_dict()["sensors"] == helmholtz.to_dict()["sensors"]


def test_extends_a_file_whose_probe_path_is_relative_to_that_file(tmp_path):
    (tmp_path / "probes").mkdir()
    PAPER_PROBE.replace(damping_per_s=0.5).to_yaml(tmp_path / "probes" / "slow.yaml")
    (tmp_path / "probes" / "slow_scene.yaml").write_text("probe: slow.yaml\nseed: 7\n")
    (tmp_path / "mine.yaml").write_text("extends: probes/slow_scene.yaml\nname: mine\n")
    mine = load_scenario(tmp_path / "mine.yaml")
    assert (mine.name, mine.seed, mine.probe.damping_per_s) == ("mine", 7, 0.5)


def test_an_extends_cycle_and_an_unknown_base_are_refused(tmp_path):
    (tmp_path / "a.yaml").write_text("extends: b.yaml\n")
    (tmp_path / "b.yaml").write_text("extends: a.yaml\n")
    with pytest.raises(ValueError, match=r"extends forms a cycle: b.yaml → a.yaml → b.yaml"):
        load_scenario(tmp_path / "a.yaml")
    with pytest.raises(ValueError, match=r"extends = 'no_such_base' is neither a YAML file .*'base', 'anti_helmholtz'"):
        Scenario.from_dict({"extends": "no_such_base"})
    with pytest.raises(ValueError, match=r"extends = 3 must be a scenario name"):
        Scenario.from_dict({"extends": 3})


def test_the_code_and_the_shipped_scenes_share_one_seed():
    assert Scenario().seed == Scenario.from_dict({}).seed == load_scenario().seed == 1


BAD_SCENARIO_FILES = {  # scene.yaml's text, and its refusal after the file's name
    "a NaN": ("noise: {mains_t: .nan}\n", "noise.mains_t = nan must be a finite number"),
    "text for a number": ('excitation: {gap_s: "1e1"}\n', "excitation.gap_s = '1e1' is not a number"),
    "a probe of a list": (
        "probes:\n  - {pose: {magnet_position_m: [0, 0, 0]}}\n  - {pose: {magnet_position_m: [0, 1e-3, .inf]}}\n",
        r"probes\[1\].pose.magnet_position_m = \[0, 0.001, inf\] must be a finite 3-vector",
    ),
    "magnets too close": (
        "probes:\n  - {pose: {magnet_position_m: [0, 0, 0]}}\n  - {pose: {magnet_position_m: [0, 5e-3, 0]}}\n",
        r"probes\[1\].pose.magnet_position_m = \[0.0, 0.005, 0.0\] is 5.00 mm from probes\[0\].pose.magnet_position_m"
        r" = \[0.0, 0.0, 0.0\]: magnets must be more than 7.78 mm apart \(twice the sum of their levers\) .*",
    ),
    "a field source": (
        "environment:\n  sources: [{type: uniform, field_t: [0, 0, 0]}, {type: uniform, field_t: [1e-6, 0]}]\n",
        r"environment.sources\[1\].field_t = \[1e-06, 0\] must be a finite 3-vector",
    ),
    "a probe file's value": ("probe: probe.yaml\n", r"probe: probe file .*probe.yaml: f00_hz = nan must be .*"),
    "a base file's text": ("extends: base_of_mine.yaml\n", r"scenario .*base_of_mine.yaml: not valid YAML: line 2, .*"),
    "a key twice": ("seed: 1\nseed: 2\n", "not valid YAML: line 2, column 1: key 'seed' is given twice"),
    "a count that is no integer": (
        "integrator: {substeps: true}\n",
        r"integrator.substeps = True must be an integer in \[1, 1000\]",
    ),
}


@pytest.mark.parametrize("case", BAD_SCENARIO_FILES)
def test_a_bad_scenario_file_is_one_line_naming_the_file_key_and_value(tmp_path, case):
    text, message = BAD_SCENARIO_FILES[case]
    (tmp_path / "probe.yaml").write_text(PAPER_PROBE.yaml_text().replace("f00_hz: 112.48", "f00_hz: .nan"))
    (tmp_path / "base_of_mine.yaml").write_text("seed: [1\n")
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    with pytest.raises(ValueError) as refused:
        load_scenario(path)
    assert re.fullmatch(f"scenario {re.escape(str(path))}: {message}", str(refused.value)), refused.value


def test_scenario_numbers_are_read_as_yaml_1_2(tmp_path):
    """The noise levels as the docs write them (1e-8, no dot): numbers, not text."""
    path = tmp_path / "scene.yaml"
    path.write_text("noise: {mains_t: 1e-8, sensor_white_t_per_rthz: 1E-11}\nexcitation: {excite_s: .5e0}\n")
    scenario = load_scenario(path)
    assert (scenario.noise.mains_t, scenario.noise.sensor_white_t_per_rthz) == (1e-8, 1e-11)
    assert scenario.excitation.excite_s == 0.5
