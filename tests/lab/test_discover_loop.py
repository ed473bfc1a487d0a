"""The loop that closes itself: ``mows lab add --auto --discover`` saves the plugin of the term
found beyond the catalog beside the table, adds it, refits and prints the error falling with the
parameter and its reading; ``--save-plugin FILE`` writes the plugin file alone.

The table is exact physics (mows.lab.data.synthetic) of tests/lab/test_discovery.py: 96 rows in
0.43 mT at 2° ring-downs, the temperature scattered over 293–303 K, and a moment that falls by
1e-3/K from the probe's reference temperature, planted to first order (β0·c·B∥·(T − T_ref))."""

import re

import numpy as np

from lab.test_discovery import FIELD, MOMENT_PER_K, moment_temperature_hz, rows, table
from mows.cli.main import main
from mows.lab import load_plugins
from mows.lab.data import synthetic
from mows.physics.probe import PAPER_PROBE

FIELD_CASE_SEED = 1


def _table_csv(directory):
    theta0, columns = rows()
    truth = synthetic.true_frequency_hz(PAPER_PROBE, FIELD, np.radians(theta0), np.radians(2.0))
    base = table((theta0, columns, truth), FIELD_CASE_SEED)
    measured = base.with_columns(f_hz=base.f_hz + moment_temperature_hz(base))
    path = directory / "table.csv"
    measured.to_csv(path)
    return path


def test_add_discover_saves_the_plugin_beside_the_table_and_the_error_falls(tmp_path, capsys):
    path = _table_csv(tmp_path)
    assert main(["lab", "add", str(path), "--auto", "--discover", "--no-cv"]) == 0
    out = capsys.readouterr().out
    saved = tmp_path / "discovered_moment_temperature_k.py"
    (effect,) = load_plugins([saved])  # the file alone, loadable as written
    assert effect.name == "discovered_moment_temperature_k"
    history = re.findall(r"^\s+\d+\s+([\d.]+)\s+[-\d.]+\s+\S+\s+(.*)$", out.split("error history:")[1], re.M)
    chi2 = [float(value) for value, _ in history]
    assert "add discovered_moment_temperature_k" in history[-1][1], history
    assert chi2[-1] <= 1.5 < chi2[-2], chi2
    assert "verdict: adequate" in out
    line = next(line for line in out.splitlines() if line.strip().startswith("discovered_moment_temperature_k.py:"))
    assert "the moment's temperature coefficient" in line
    value, std = (float(x) for x in re.search(r"c = (\S+) ± (\S+) 1/K", line).groups())
    assert abs(value - MOMENT_PER_K) <= 3 * std, line


def test_save_plugin_writes_the_plugin_file_alone(tmp_path, capsys):
    path = _table_csv(tmp_path)
    output = tmp_path / "found.py"
    assert main(["lab", "diagnose", str(path), "--effects", "static_deflection (at physics)", "--no-cv",
                 "--save-plugin", str(output)]) == 0  # fmt: skip
    out = capsys.readouterr().out
    assert f"wrote {output}: the plugin of moment × temperature_k" in out
    text = output.read_text()
    assert text.startswith('"""') and "discovery beyond the catalog" not in text and "verdict" not in text
    (effect,) = load_plugins([output])
    assert effect.name == "discovered_moment_temperature_k"
    # An existing file is kept unless --force.
    assert main(["lab", "diagnose", str(path), "--no-cv", "--save-plugin", str(output)]) == 2
    assert output.read_text() == text
