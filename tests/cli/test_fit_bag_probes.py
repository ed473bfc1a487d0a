"""`mows fit BAG --probes SPEC`: a driver's bag of three probes ringing in each window, fitted
offline jointly, as the estimator node fits them with its ``probes`` parameter.

Independent physics: the simulator integrates the three coupled probes in the anti-Helmholtz
scene's field (docs/multi_probe.md) and the driver's session rings them with one multi-tone
excitation per repeat; each probe's truth is its frequency at zero swing in the scene's field
and its neighbours' (:meth:`SimulatedDevice.expected_frequencies_hz`, harmonic balance of the
static coupled potential), which the probes' f00s (100, 112.5, 125 Hz) miss by 0.06–0.5 Hz.
Tones of 30 mA swing the probes by 1–3°: the amplitude's own shift of the frequency
(≈ f·A²/16 of the field's share) stays far below σ. Each probe's fit must lie within 4σ of its
truth, and `mows lab compare` of the table must keep the probes apart: one f00 per probe, χ²/dof
within the 99 % bound of χ² with 15 degrees of freedom (2.0); one f00 for all three would put it
near (12 Hz / 2 mHz)² ≈ 4e7. `mows lab ringdown --probes` diagnoses each probe inside each joint
window, its pieces fitted jointly with its neighbours'.

Each claim holds for a session without tuning rounds (``bag``: every tone at its probe's f00) and
for one with the driver's default tuning rounds (``tuned_bag``: the tones of the tuning windows
and of the measurements after them move to each probe's fitted resonance, 0.06–0.5 Hz from its
f00). A probe that rang but is left out of ``--probes`` is named and never fitted, and takes no
line from the probes listed: its line, at the tone announced for it, is fitted beside theirs.
"""

import csv
import dataclasses
import json
import math
import re

import numpy as np
import pytest

from mows.cli.main import main
from mows.device.cycle.phases import CycleSettings
from mows.sim.scenario import load_scenario
from recorded_bags import record_session

SCENE = load_scenario("three_probes")
SETTINGS = CycleSettings(
    excite_s=0.5, ringdown_s=0.5, gap_s=0.1, repeats=6, turn_settle_s=0.2, excitation_current_a=0.03, tuning_steps=0
)
STAGE_RAD = 0.3
# The scene's pair stands above the probes, along the rotation plane's normal.
GEOMETRY = ["--sensor-distance-m", "0.02", "--sensor-spacing-m", "0.03", "--sensor-direction", "0", "0", "1"]
MAX_PULL = 4.0
MAX_CHI2_DOF = 2.0


def probes_spec(ids):
    """The --probes text of the scene's probes ``ids``: each by its f00 and its magnet's place."""
    entries = []
    for k in ids:
        placed = SCENE.probes[k]
        where = ", ".join(repr(x) for x in placed.pose.magnet_position_m)
        entries.append(f"{k}: {{f00_hz: {placed.probe.f00_hz!r}, position_m: [{where}]}}")
    return "{" + ", ".join(entries) + "}"


BAGS = ["bag", "tuned_bag"]


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    return record_session(tmp_path_factory.mktemp("probes") / "recorded", SCENE, STAGE_RAD, SETTINGS, seed=1)


@pytest.fixture(scope="module")
def tuned_bag(tmp_path_factory):
    """A session with the driver's default tuning rounds before the measurements."""
    settings = dataclasses.replace(SETTINGS, tuning_steps=CycleSettings().tuning_steps)
    return record_session(tmp_path_factory.mktemp("tuned") / "recorded", SCENE, STAGE_RAD, settings, seed=1)


@pytest.mark.parametrize("recorded", BAGS)
def test_each_probe_is_fitted_jointly_at_its_coupled_frequency_and_tabled_apart(recorded, request, tmp_path, capsys):
    path, truth = request.getfixturevalue(recorded)
    table = tmp_path / "fits.csv"
    assert main(["fit", str(path), *GEOMETRY, "--probes", probes_spec((0, 1, 2)), "--csv", str(table)]) == 0
    out = capsys.readouterr().out
    assert "18 of 18 probes' fits OK in 6 ring-downs" in out, out
    assert len(re.findall(r"^cycle 1 repeat \d probe [012] θ0", out, re.M)) == 18
    rows = list(csv.DictReader(open(table)))
    assert sorted(float(r["probe"]) for r in rows) == [0.0] * 6 + [1.0] * 6 + [2.0] * 6
    for row in rows:
        pull = (float(row["f_hz"]) - truth[int(float(row["probe"]))]) / float(row["f_std_hz"])
        assert abs(pull) < MAX_PULL, row
    assert main(["lab", "compare", str(table)]) == 0
    compared = capsys.readouterr().out
    assert all(f"probe_{k}.f00_hz" in compared for k in range(3)), compared
    chi2 = float(re.search(r"χ²/dof = ([0-9.e+]+)", compared).group(1))
    assert chi2 < MAX_CHI2_DOF, compared


@pytest.mark.parametrize("recorded", BAGS)
def test_a_probe_the_windows_list_but_probes_lacks_is_a_failure_naming_it(recorded, request, tmp_path, capsys):
    path, truth = request.getfixturevalue(recorded)
    table = tmp_path / "fits.csv"
    assert main(["fit", str(path), *GEOMETRY, "--probes", probes_spec((0, 1)), "--csv", str(table)]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if " probe 2 θ0" in line]
    assert len(lines) == 6
    assert all("BAD_FIT: probe 2 rang in this window but is not in the probes parameter" in line for line in lines)
    assert all(" f = " not in line for line in lines)
    rows = list(csv.DictReader(open(table)))
    assert sorted(float(r["probe"]) for r in rows) == [0.0] * 6 + [1.0] * 6
    for row in rows:  # each at its own line, not at the next one up
        assert abs(float(row["f_hz"]) - truth[int(float(row["probe"]))]) < MAX_PULL * float(row["f_std_hz"]), row


def test_tuning_windows_are_fitted_per_probe_at_the_tones_the_driver_announced(tuned_bag, tmp_path, capsys):
    """The two tuning windows ring the three probes at their f00, then at their first fits:
    with ``--tuning`` each probe of each is fitted at its own line, within 4σ of its truth."""
    path, truth = tuned_bag
    table = tmp_path / "fits.csv"
    assert main(["fit", str(path), *GEOMETRY, "--probes", probes_spec((0, 1, 2)), "--tuning", "--csv", str(table)]) == 0
    assert "24 of 24 probes' fits OK in 8 ring-downs" in capsys.readouterr().out
    rows = list(csv.DictReader(open(table)))
    assert sorted(float(r["probe"]) for r in rows) == [0.0] * 8 + [1.0] * 8 + [2.0] * 8
    for row in rows:
        pull = (float(row["f_hz"]) - truth[int(float(row["probe"]))]) / float(row["f_std_hz"])
        assert abs(pull) < MAX_PULL, row


@pytest.mark.parametrize(
    "spec, said",
    [
        ("[0, 1, 2]", "is not a mapping"),
        ("{0: 100.0, 1: 100.5, 2: 125.0}", "closer than 1 Hz"),
        ("{0: missing.yaml}", "missing.yaml"),
    ],
)
def test_a_malformed_probes_is_refused_in_one_line(bag, tmp_path, capsys, spec, said):
    path, _ = bag
    table = tmp_path / "fits.csv"
    assert main(["fit", str(path), "--probes", spec, "--csv", str(table)]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and error.startswith("mows fit: error: --probes") and said in error, error
    assert not table.exists()


def test_several_probes_without_probes_are_refused_naming_them(bag, capsys):
    path, _ = bag
    assert main(["fit", str(path)]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "probes 0, 1, 2" in error and "--probes '{0: F00_HZ" in error, error


def test_calibrate_refuses_a_bag_of_several_probes_in_its_own_words(bag, tmp_path, capsys):
    path, _ = bag
    assert main(["calibrate", str(path), "-o", str(tmp_path / "p.yaml")]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "probes 0, 1, 2" in error and "a calibration is of one probe" in error
    assert "--probes" not in error and not (tmp_path / "p.yaml").exists(), error


@pytest.mark.parametrize("recorded", BAGS)
def test_lab_ringdown_diagnoses_each_probe_inside_each_joint_window(recorded, request, capsys):
    """Each probe's pieces, fitted jointly with its neighbours, average to its truth within 4σ,
    and at swings of 1–3° (a predicted chirp below 0.1 mHz, a piece's σ 15–150 mHz) every
    probe's verdict is a constant frequency."""
    path, truth = request.getfixturevalue(recorded)
    assert main(["lab", "ringdown", str(path), *GEOMETRY, "--probes", probes_spec((0, 1, 2)), "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert sorted(item["probe_id"] for item in found) == [0] * 6 + [1] * 6 + [2] * 6
    for item in found:
        assert item["verdict"] == "constant", item
        f = np.array([p["frequency_hz"] for p in item["pieces"]])
        w = np.array([p["frequency_std_hz"] for p in item["pieces"]]) ** -2.0
        assert abs((w @ f) / w.sum() - truth[item["probe_id"]]) < MAX_PULL / math.sqrt(w.sum()), item


@pytest.mark.parametrize("recorded", BAGS)
def test_lab_ringdown_names_a_probe_the_windows_list_but_probes_lacks(recorded, request, capsys):
    path, _ = request.getfixturevalue(recorded)
    assert main(["lab", "ringdown", str(path), *GEOMETRY, "--probes", probes_spec((0, 1)), "--cycle", "1"]) == 0
    out = capsys.readouterr().out
    assert out.count("probe 2 θ0 97.19°: not diagnosed: probe 2 rang in this window but is not in the probes") == 6
    # The probes listed are diagnosed at their own lines, as with all three listed.
    assert out.count("verdict: constant") == 12, out
    for k in (0, 1):
        assert len(re.findall(rf"^cycle 1 repeat \d probe {k} θ0 .*: constant-frequency fit: f = ", out, re.M)) == 6


def test_lab_ringdown_diagnoses_the_tuning_windows_of_each_probe(tuned_bag, capsys):
    """With ``--tuning`` the two tuning windows are diagnosed too, each probe at the tone the
    driver announced for it (its f00, then its first fit), its pieces averaging to its truth."""
    path, truth = tuned_bag
    spec = probes_spec((0, 1, 2))
    assert main(["lab", "ringdown", str(path), *GEOMETRY, "--probes", spec, "--tuning", "--json"]) == 0
    found = json.loads(capsys.readouterr().out)
    assert sorted(item["probe_id"] for item in found) == [0] * 8 + [1] * 8 + [2] * 8
    for item in found:
        assert item["verdict"] == "constant", item
        f = np.array([p["frequency_hz"] for p in item["pieces"]])
        w = np.array([p["frequency_std_hz"] for p in item["pieces"]]) ** -2.0
        assert abs((w @ f) / w.sum() - truth[item["probe_id"]]) < MAX_PULL / math.sqrt(w.sum()), item
