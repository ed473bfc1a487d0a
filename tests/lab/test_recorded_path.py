"""The whole path on raw signals: a recorded bag → ``mows fit --csv`` → ``mows lab add --auto``.

Requirement: a scientist records a rotation sweep, fits it with our estimator and hands our
own table to the lab with the static reference; the lab must name the physics the signals
carry (or report an alias group holding it) at χ²/dof ≤ 1.5 and add nothing to a control,
with false alarms ≤ 1 in 40 seeds. Two control seeds run here (a run costs 20–50 s); over
seeds 0–39 this path measured no false alarm (40 of 40 adequate, nothing added beyond the
finite amplitude at physics; docs/model_lab.md), and tests/lab/test_hidden_effects.py holds
the 40-seed bound on tables from exact physics.
Nothing here is the lab's physics: the simulator integrates the equation of motion in each
scene's actual sources (every ring-down driven to the housing stop, sensor noise), the bag
holds its raw fluxgate blocks (tests/recorded_bags.py), and the estimator's table carries
whatever start swings its single fits gave (wrong and confident in strong fields; the lab takes
the start swing from the stop). 12 orientations × 2 sweeps per scene, one bag and one
analysis per scene for the module. The warming scenes' logs are joined to the table by
device time, as a user joins a logger's file.
"""

import contextlib
import csv
import dataclasses
import io
import json
import math

import numpy as np
import pytest

from mows.cli import main as cli
from mows.lab import reference_at
from mows.physics.field import UniformField
from mows.sim.scenario import load_scenario
from recorded_bags import record_cycles

ANGLES_DEG = list(np.arange(0.0, 360.0, 30.0)) * 2
SEED = 0
MOMENT_PER_K = -1.2e-3
KNOWN_PHYSICS = {"finite_amplitude", "static_deflection", "damping_shift", "housing_stop"}

pytestmark = pytest.mark.slow


def _with_source(name: str, source):
    base = load_scenario(name)
    return base.replace(environment=dataclasses.replace(base.environment, sources=(*base.environment.sources, source)))


def _warming(rate_k_per_s: float):
    base = load_scenario("paper_largest_spacing")
    return base.replace(environment=dataclasses.replace(base.environment, temperature_rate_k_per_s=rate_k_per_s))


def _warming_magnet():
    """A magnet losing 0.12 %/K of its moment (NdFeB) while the probe warms 0.3 K/s, ~10 K over the
    run, in 0.43 mT: the field's share of the frequency changes by ~20 mHz, angle by angle."""
    base = _with_source("paper_largest_spacing", UniformField((4e-4, 1.5e-4, 0.0)))
    return base.replace(
        probe=base.probe.replace(moment_temp_coeff_per_k=MOMENT_PER_K),
        environment=dataclasses.replace(base.environment, temperature_rate_k_per_s=0.3),
    )


SCENES = {
    "control": lambda: load_scenario("paper_largest_spacing"),
    "strong_field": lambda: _with_source("paper_largest_spacing", UniformField((3.4e-3, 0.0, 0.0))),
    "anti_helmholtz": lambda: load_scenario("anti_helmholtz"),
    "tilted_plane": lambda: load_scenario("tilted_plane"),
    "nearby_coil": lambda: load_scenario("nearby_coil"),
    "temperature": lambda: _warming(5e-3),
    "moment_temperature": _warming_magnet,
}


@pytest.fixture(scope="module")
def path(tmp_path_factory):
    """scene → (scenario, the lab's JSON report, the table's rows as read back), each run once."""
    found, files, bags = {}, {}, {}

    def run(scene, seed=SEED):
        if (scene, seed) not in found:
            scenario = SCENES[scene]()
            folder = tmp_path_factory.mktemp(scene)
            bag, records = record_cycles(folder / "bag", scenario, ANGLES_DEG, seed)
            table = folder / "fits.csv"
            assert cli.main(["fit", str(bag), "--csv", str(table)]) == 0
            if scenario.environment.temperature_rate_k_per_s:
                _join_temperature_log(table, scenario, records)
            probe = folder / "probe.yaml"  # the user's probe file knows nothing of the magnet's temperature
            scenario.probe.replace(moment_temp_coeff_per_k=0.0).to_yaml(probe)
            reference = folder / "scenario.yaml"
            scenario.to_yaml(reference)
            files[scene, seed] = table, probe, reference
            bags[scene, seed] = bag
            found[scene, seed] = scenario, _lab(*files[scene, seed]), list(csv.DictReader(open(table)))
        return found[scene, seed]

    run.files, run.bags = files, bags

    return run


def _join_temperature_log(table, scenario, records):
    """Add the device's temperature at each row's time (the first ring-down's coil-off is t_s = 0)."""
    first = records[0]
    start_s = (first.block.samples.first_sample_index + first.coil_off_index) / first.sample_rate_hz
    rows = list(csv.DictReader(open(table)))
    for row in rows:
        row["temperature_k"] = repr(float(scenario.environment.temperature_at(start_s + float(row["t_s"]))))
    with open(table, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


def _lab(table, probe, reference, plugins=()) -> dict:
    """``mows lab add --auto`` on the table (with ``plugins`` files), its JSON report."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        status = cli.main(
            ["lab", "add", str(table), "--auto", "--probe", str(probe), "--reference", str(reference)]
            + [arg for plugin in plugins for arg in ("--plugin", str(plugin))]
            + ["--no-cv", "--json"]
        )
    assert status == 0, out.getvalue()
    return json.loads(out.getvalue())


def names(labels) -> set:
    return {label.removesuffix(" (at physics)") for label in labels}


def found(report, expected: set) -> set:
    """The expected effects the lab named: in the model, or in a reported alias group with a
    member the model holds."""
    held = names(report["effects"])
    grouped = {m for g in report["groups"] if set(g["members"]) & held for m in g["members"]}
    return expected & (held | grouped)


def assert_named(report, expected: set, chi2_dof: float = 1.5):
    history = [step["change"] for step in report["history"]]
    assert found(report, expected) == expected, (report["effects"], report["groups"], history)
    extra = names(report["effects"]) - expected - KNOWN_PHYSICS
    assert not extra, (extra, history)
    assert report["final"]["chi2_dof"] <= chi2_dof, (report["final"]["chi2_dof"], history)


def test_our_table_is_marked_and_every_ring_down_is_a_row(path):
    _, report, rows = path("strong_field")
    assert len(rows) == len(ANGLES_DEG), report["notes"]
    assert all(float(row["mows_table_format"]) == 1.0 for row in rows)


@pytest.mark.parametrize("seed", [SEED, SEED + 1])
def test_the_control_adds_nothing_but_known_physics(path, seed):
    _, report, _ = path("control", seed)
    assert names(report["effects"]) <= KNOWN_PHYSICS, report["history"]
    assert report["verdict"] == "adequate", report["verdict_explanation"]


def test_a_strong_uniform_field_is_the_deflection_and_the_amplitude_from_the_stop(path):
    """3.4 mT along x: at θ0 = 90° the rest angle turns by ~12°, so the swing starts ~12° from rest
    where the stop is 24°; the estimator's single fits leave θmax undetermined there. The lab
    names the deflection and the finite amplitude, the start swing from the stop, and ends
    adequate at χ²/dof 0.87 (seed 1: 0.69). Both need the lopsided potential's second harmonic:
    in the frequency (first-harmonic balance alone is 3–5 mHz low at θ0 = 90°, 150°, 210°) and
    in the start swing (the first harmonic of a swing that turns at the stop lies 0.08°–0.13°
    beyond the stop's distance from rest); without them the model ended at 4.1. The amplitude's
    free strength ends at 0.993 ± 0.0014, not 1: the fit starts 3 ms after the switch-off
    (A² 1.1 % smaller) and the probe turns 0.05° into the compliant stop, neither in the table."""
    _, report, _ = path("strong_field")
    assert_named(report, {"static_deflection", "finite_amplitude"})
    assert report["verdict"] == "adequate", report["verdict_explanation"]


def test_an_anti_helmholtz_gradient_is_the_transverse_gradient(path):
    """Judged by the lab's own test (adequate: χ² consistent with its 23 dof at p ≥ 0.005 and no
    significant structure), not a fixed χ²/dof of 1.5, which a right model exceeds in 1 of 17
    seeds at 23 dof. Over seeds 0–9 this scene ended adequate in 9 of 10, at χ²/dof 0.89–1.64;
    its mean over them, 1.33 where a right model gives 1.00 ± 0.09, and seed 1 (2.68, structure:
    harmonic 1 of θ0 along b_perp_t, 0.73 ± 0.16 mHz) say that something small of this scene is
    not yet in the model."""
    _, report, _ = path("anti_helmholtz")
    assert_named(report, {"transverse_gradient", "finite_amplitude"}, chi2_dof=math.inf)
    assert report["verdict"] == "adequate", (report["final"]["chi2_dof"], report["verdict_explanation"])


@pytest.mark.parametrize("scene", ["control", "anti_helmholtz", "strong_field"])
def test_the_bag_maps_offline_to_the_scenes_field_and_gradient(path, scene):
    """`mows map BAG --refit`: the bag's raw ring-downs fitted again and decomposed as the mapper
    does, one sweep of both turns, lands within 4σ of the field and gradient at the probe. In
    3.4 mT the field needs each ring-down's swing to 0.01°: the swing released at the stop has
    decayed by 0.5 % when the fit's window starts 3 ms later. This seed's Bx: +3.7σ without that
    decay, −3.4σ with it (seeds 1–5: +4.5σ to +5.5σ, then −2.0σ to −2.5σ); the rest is the
    probe's nominal stop, which the fits do not determine here (docs/physics.md §6.4). This probe
    file states no σ for its stop, so the map carries 1°: 2.6 µT of Bx's σ (the test below states
    the simulated housing's 0.05°)."""
    scenario, _, _ = path(scene)
    _, probe, _ = path.files[scene, SEED]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert cli.main(["map", str(path.bags[scene, SEED]), "--refit", "--probe", str(probe), "--json"]) == 0
    (sweep,) = json.loads(out.getvalue())["sweeps"]
    (mapped,) = sweep["maps"]
    assert sweep["ok"] and mapped["points"] == len(ANGLES_DEG), sweep["message"]
    field, gradient = reference_at(scenario)
    truth = {"field_t": field[:2], "gradient_t_per_m": [gradient[0, 0], gradient[0, 1], gradient[1, 1]]}
    for name, std in (("field_t", "field_std_t"), ("gradient_t_per_m", "gradient_std_t_per_m")):
        pulls = (np.array(mapped[name]) - truth[name]) / np.array(mapped[std])
        assert np.all(np.abs(pulls) < 4.0), (name, pulls, sweep["message"])


def test_a_tilted_plane_is_gravity(path):
    _, report, _ = path("tilted_plane")
    assert_named(report, {"gravity"})


def test_a_nearby_coil_is_its_gradient_deflection_and_curvature(path):
    _, report, _ = path("nearby_coil")
    assert_named(report, {"transverse_gradient", "finite_amplitude", "static_deflection", "field_curvature"})


def test_a_temperature_log_is_thermal_drift(path):
    _, report, _ = path("temperature")
    assert_named(report, {"thermal_drift"})
    assert math.isfinite(report["final"]["chi2_dof"])


MOMENT_PLUGIN = """
from mows.lab import effect


@effect(name="moment_temperature", parameters={"c_per_k": (0.0, -1e-2, 1e-2, "1/K")},
        explanation="the magnet's moment changes with temperature: m(T) = m·(1 + c·(T − 293.15 K))")
def moment_temperature(rows, c_per_k):
    return {"moment_scale": c_per_k * (rows.temperature_k - 293.15)}
"""


def test_a_moment_falling_with_temperature_needs_the_users_plugin(path, tmp_path):
    """Outside the catalog, on the whole path (simulator bag → ``mows fit --csv`` → ``mows lab
    add --auto``): the lab keeps only the physics that is there (the spring's drift, the
    deflection and the amplitude at physics; before the search was held to physics it also took
    a tilted plane or a moment-scale error) and ends ``unexplained_structure`` (χ²/dof 215 at
    seed 0), its search beyond the catalog naming the moment's temperature coefficient
    (the moment channel times T), with it as the plugin. The
    user's plugin written as physics (the docs' worked example, a moment scale through the
    full potential) ends adequate (χ²/dof 1.35) and reads the coefficient back
    (−1.18e-3 ± 0.02e-3)."""
    _, report, _ = path("moment_temperature")
    assert report["verdict"] == "unexplained_structure", report["verdict_explanation"]
    assert report["final"]["chi2_dof"] > 1.5, report["history"]
    assert names(report["effects"]) <= KNOWN_PHYSICS | {"thermal_drift"}, report["history"]
    terms = report["discovery"]["terms"]
    assert terms and terms[0]["family"] == "moment_temperature", report["discovery"]["summary"]
    assert '"moment_scale": c * (rows.temperature_k - 293.15)' in terms[0]["plugin"]
    plugin = tmp_path / "moment_temperature.py"
    plugin.write_text(MOMENT_PLUGIN)
    explained = _lab(*path.files["moment_temperature", SEED], plugins=[plugin])
    assert_named(explained, {"moment_temperature", "thermal_drift", "static_deflection"})
    coefficient = explained["final"]["parameters"]["moment_temperature.c_per_k"]
    assert abs(coefficient["value"] - MOMENT_PER_K) < 3 * coefficient["std"], coefficient


def test_in_3_4_mt_the_maps_pulls_stay_within_2_sigma_over_10_seeds(tmp_path):
    """The strong-field scene's bag → `mows map BAG --refit` over seeds 0–9, the probe file stating
    its stop to ±0.05° (the simulated lever is released 0.03°–0.04° beyond its housing: the
    compliant stop and the cut before the turning point). The fits do not determine θmax here,
    so B rests on that stop, 26 nT per 0.01°: its σ is carried into B and G as one error shared
    by the sweep. Every pull of Bx, By, Gxx, Gxy, Gyy within ±2σ, and Bx's mean pull within 2σ
    of its Monte Carlo error (1/√10). Without the stop's σ, Bx read −0.8σ to −2.6σ (mean −1.76,
    4 of 10 beyond −2σ); with it −0.24σ to −0.77σ."""
    scenario = SCENES["strong_field"]()
    probe = tmp_path / "probe.yaml"
    scenario.probe.replace(theta_stop_std_rad=math.radians(0.05)).to_yaml(probe)
    field, gradient = reference_at(scenario)
    truth = np.r_[field[:2], gradient[0, 0], gradient[0, 1], gradient[1, 1]]
    pulls = []
    for seed in range(10):
        bag, _ = record_cycles(tmp_path / f"bag{seed}", scenario, ANGLES_DEG, seed)
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            assert cli.main(["map", str(bag), "--refit", "--probe", str(probe), "--json"]) == 0
        (mapped,) = json.loads(out.getvalue())["sweeps"][0]["maps"]
        value = np.r_[mapped["field_t"], mapped["gradient_t_per_m"]]
        std = np.r_[mapped["field_std_t"], mapped["gradient_std_t_per_m"]]
        pulls.append((value - truth) / std)
    pulls = np.array(pulls)
    assert np.all(np.abs(pulls) < 2.0), pulls.round(2)
    assert abs(pulls[:, 0].mean()) < 2.0 / math.sqrt(10), pulls[:, 0].round(2)
