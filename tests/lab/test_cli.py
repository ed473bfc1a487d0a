"""`mows lab compare | diagnose | add | report`: text, JSON schema, HTML, and user errors."""

import fcntl
import json
import os
import pty
import struct
import subprocess
import sys
import termios

import numpy as np
import pytest

import mows.cli.lab
from lab.tables import tilted_table
from mows.cli.main import main
from mows.lab import FrequencyModel, ProbeSet, catalog, read_csv
from mows.lab.report.html_report import sweep_curve
from mows.physics.probe import PAPER_PROBE


@pytest.fixture(scope="module")
def tilted_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("lab") / "tilted.csv"
    tilted_table(amplitude_deg=2.0).to_csv(path)
    return path


def test_diagnose_json_has_the_documented_keys(tilted_csv, capsys):
    assert main(["lab", "diagnose", str(tilted_csv), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert {"base", "candidates", "groups", "history", "verdict", "structure"} <= set(result)
    assert set(result["base"]) >= {"chi2_dof", "n"} and result["base"]["n"] == 48
    assert result["verdict"] == "effect_missing"
    first = result["candidates"][0]
    assert {"effect", "delta_bic", "p_value", "chi2_dof_after", "parameters"} <= set(first)
    assert first["effect"] == "gravity" and first["delta_bic"] > 10
    assert all(set(step) >= {"effects", "chi2_dof", "bic", "cv_rms"} for step in result["history"])


def test_add_auto_prints_the_error_history(tilted_csv, capsys):
    assert main(["lab", "add", str(tilted_csv), "--auto"]) == 0
    out = capsys.readouterr().out
    assert "error history" in out and "eq6 + gravity" in out and "verdict: adequate" in out
    assert main(["lab", "add", str(tilted_csv), "gravity", "--json"]) == 0
    history = json.loads(capsys.readouterr().out)["history"]
    assert [step["effects"] for step in history] == [[], ["gravity"]]
    assert history[1]["cv_rms"] < history[0]["cv_rms"]


def test_compare_and_report(tilted_csv, tmp_path, capsys):
    assert main(["lab", "compare", str(tilted_csv)]) == 0
    out = capsys.readouterr().out
    assert "harmonic" in out and "verdict: unexplained_structure" in out
    page = tmp_path / "page.html"
    assert main(["lab", "report", str(tilted_csv), "--auto", "-o", str(page), "--no-cv"]) == 0
    text = page.read_text()
    pictures = text.count("data:image/png;base64,") + text.count("<svg")  # the residuals are inline SVG
    assert pictures >= 6 and "<svg" in text and "gravity" in text


@pytest.mark.parametrize(
    "args, words",
    [
        (["lab", "compare", "/nonexistent.csv"], ["cannot read"]),
        (["lab", "add", "TABLE", "no_such_effect"], ["unknown effect", "no_such_effect"]),
        (["lab", "diagnose", "TABLE", "--probe", "BADPROBE"], ["probe file", "moment_am2"]),
        (["lab", "diagnose", "TABLE", "--plugin", "nothing_like_this"], ["nothing_like_this"]),
    ],
)
def test_user_errors_are_one_line_messages(tilted_csv, tmp_path, capsys, args, words):
    bad_probe = tmp_path / "probe.yaml"
    bad_probe.write_text("f00_hz: 112\n")
    args = [str(tilted_csv) if a == "TABLE" else str(bad_probe) if a == "BADPROBE" else a for a in args]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    for word in words:
        assert word in err


def test_report_polar_curve_passes_through_the_model_at_measured_orientations(tilted_csv):
    table = read_csv(tilted_csv)
    fit = (FrequencyModel(ProbeSet.one(PAPER_PROBE)) + catalog()["gravity"]).fit(table)
    rows = table.sweep_ids == 0
    at_measured = sweep_curve(fit, rows, table.theta0_deg[rows])
    np.testing.assert_allclose(at_measured, fit.prediction_hz[rows], rtol=0, atol=1e-9)
    # Between measured orientations the curve is the model itself, not a straight chord: at the
    # midpoints it departs from the mean of its neighbours by the curvature of Δf(θ0).
    angles = np.unique(table.theta0_deg[rows])
    middle = sweep_curve(fit, rows, angles[:-1] + np.diff(angles) / 2)
    chord = (
        fit.prediction_hz[rows][np.argsort(table.theta0_deg[rows])][:-1]
        + fit.prediction_hz[rows][np.argsort(table.theta0_deg[rows])][1:]
    ) / 2
    assert np.max(np.abs(middle - chord)) > 1e-5


def test_diagnose_separates_a_group_on_a_table_without_amplitudes(tilted_csv, tmp_path, capsys):
    """amplitude_deg is optional: the what-if variants (one halves the amplitude) must still
    join the table they extend."""
    table = read_csv(tilted_csv)
    bare = tmp_path / "no_amplitude.csv"
    type(table)({k: v for k, v in table.columns.items() if k != "amplitude_deg"}).to_csv(bare)
    assert main(["lab", "diagnose", str(bare), "--json"]) == 0
    groups = json.loads(capsys.readouterr().out)["groups"]
    assert groups and all(group["separation"] for group in groups)


def test_a_long_table_is_analysed_on_a_stated_subsample_without_a_progress_bar_in_json(
    tilted_csv, tmp_path, capsys, monkeypatch
):
    monkeypatch.setattr(mows.cli.lab, "MAX_ROWS", 2000)  # the rule, at a limit a test can pass quickly
    table = read_csv(tilted_csv)
    copies = mows.cli.lab.MAX_ROWS // len(table) + 2
    long = tmp_path / "long.csv"
    table.subset(np.tile(np.arange(len(table)), copies)).to_csv(long)
    assert main(["lab", "compare", str(long), "--json", "--no-cv"]) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    assert report["base"]["n"] == mows.cli.lab.MAX_ROWS
    assert any(
        f"{copies * len(table)} rows: analysed on a random subsample of {mows.cli.lab.MAX_ROWS}" in note
        for note in report["notes"]
    )
    assert captured.err == ""  # no progress bar (stderr is no terminal here, and --json)
    assert main(["lab", "compare", str(long), "--json", "--no-cv", "--all-rows"]) == 0
    assert json.loads(capsys.readouterr().out)["base"]["n"] == copies * len(table)


def test_a_terminal_sees_the_stages_progress_and_the_work_inside_diagnose(tilted_csv):
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a new pty is 0 columns wide
    with subprocess.Popen(
        [sys.executable, "-m", "mows.cli.main", "lab", "diagnose", str(tilted_csv)],
        stdout=subprocess.DEVNULL,
        stderr=slave,
    ) as process:
        os.close(slave)
        seen = b""
        while True:
            try:
                data = os.read(master, 4096)
            except OSError:  # the child closed its end
                break
            if not data:
                break
            seen += data
    os.close(master)
    assert process.returncode == 0
    assert b"mows lab diagnose: reading" in seen and b"stages" in seen
    # Inside the analysis: the cross-validation's folds, each candidate effect, the evaluations.
    assert b"cross-validation (folds)" in seen and b"ranking candidate effects" in seen
    assert b"model evaluations" in seen


def test_a_reference_for_a_table_with_its_own_is_refused_in_one_line(tilted_csv, capsys):
    assert main(["lab", "compare", str(tilted_csv), "--reference", "helmholtz", "--no-cv"]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1 and "already has reference columns" in error, error


def test_a_static_reference_joins_a_table_without_one(tilted_csv, tmp_path, capsys):
    """As for `mows fit --csv`'s tables: the reference columns come from the named scene."""
    table = read_csv(tilted_csv)
    bare = tmp_path / "bare.csv"
    type(table)({k: v for k, v in table.columns.items() if not k.startswith("ref_")}).to_csv(bare)
    assert main(["lab", "compare", str(bare), "--reference", "helmholtz", "--no-cv", "--json"]) == 0
    notes = json.loads(capsys.readouterr().out)["notes"]
    assert any("reference: helmholtz" in note for note in notes) and not any("no reference" in n for n in notes)
