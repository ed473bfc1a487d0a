"""Every `mows lab` command line the docs show runs verbatim (docs/command_line.md, docs/model_lab.md).

The command lines are read from the documents themselves (fenced blocks and inline code), so a
documented form that the parser rejects fails here; the plugin file is the documented one too.
The files the commands name (sweep.csv, sweeps.csv, fits.csv, probe.yaml, scenario.yaml,
coil_heating.py, moment_temperature.py, the paper's probe path, the recorded bag ``recording``,
a table of three probes with their files) are made in a scratch directory that the commands run
in.
"""

import pathlib
import re
import shlex
import shutil

import numpy as np
import pytest

from mows.cli.main import main
from mows.lab import MeasurementTable
from mows.lab.data import synthetic
from mows.physics.coupling import PlacedProbe
from mows.physics.field import SumSource, UniformField, anti_helmholtz_pair
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE
from mows.sim.scenario import load_scenario
from mows.sim.sections import Environment
from recorded_bags import record_cycles

ROOT = pathlib.Path(__file__).resolve().parents[2]
DOCUMENTS = (ROOT / "docs" / "command_line.md", ROOT / "docs" / "model_lab.md")
PAPER_PROBE_PATH = pathlib.Path("src/mows/physics/probes/paper.yaml")


def _fenced_blocks(text):
    return re.findall(r"```(\w*)\n(.*?)```", text, flags=re.S)


def documented_commands() -> list:
    """The `mows lab …` command lines of the documents, comments stripped, in order."""
    found = []
    for document in DOCUMENTS:
        text = document.read_text()
        for _, block in _fenced_blocks(text):
            found += [re.sub(r"\s#.*", "", line).strip() for line in block.splitlines() if line.startswith("mows lab ")]
        found += re.findall(r"`(mows lab [^`]+)`", text)
    return list(dict.fromkeys(found))


def documented_plugin(name: str = "coil_heating") -> str:
    """The plugin file the docs tell the user to save as ``name``.py."""
    text = (ROOT / "docs" / "model_lab.md").read_text()
    return next(block for language, block in _fenced_blocks(text) if language == "python" and f'name="{name}"' in block)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory):
    """A table with all that the documented commands use: a gradient (transverse_gradient), a
    temperature log (thermal_drift), coil currents (the plugin) and two sweeps."""
    directory = tmp_path_factory.mktemp("documented")
    sweep = synthetic.rotation_sweeps(30.0, 2)
    theta0 = sweep.pop("theta0_deg")
    source = SumSource([UniformField((3e-5, 0.0, 0.0)), anti_helmholtz_pair((0, 0, 0), (1, 0, 0), 0.05, 40, 0.5)])
    table = synthetic.synthesize(
        PAPER_PROBE,
        source,
        theta0,
        np.random.default_rng(3),
        amplitude_deg=3.0,
        temperature_k=296.0 + 0.01 * sweep["t_s"],
        coil_current_a=np.tile([0.0, 1.0, 2.0], len(theta0) // 3),
        **sweep,
    )
    table.to_csv(directory / "sweep.csv")
    table.to_csv(directory / "sweeps.csv")
    shutil.copy(ROOT / PAPER_PROBE_PATH, directory / "probe.yaml")
    (directory / PAPER_PROBE_PATH).parent.mkdir(parents=True)
    shutil.copy(ROOT / PAPER_PROBE_PATH, directory / PAPER_PROBE_PATH)
    (directory / "coil_heating.py").write_text(documented_plugin())
    # The walkthrough from a bag: its table (with a temperature log), scene and plugin.
    fitted = {name: values for name, values in table.columns.items() if not name.startswith("ref_")}
    MeasurementTable(fitted, "mows fit").to_csv(directory / "fits.csv")  # as `mows fit --csv` writes: no reference
    load_scenario("paper_largest_spacing").to_yaml(directory / "scenario.yaml")
    (directory / "moment_temperature.py").write_text(documented_plugin("moment_temperature"))
    # `mows lab add probes.csv --probe 0=a.yaml …`: three paper probes 5 cm apart on one stage.
    placed = [PlacedProbe(PAPER_PROBE, Pose(magnet_position_m=(0.05 * i, 0.0, 0.0))) for i in range(3)]
    rng = np.random.default_rng(4)
    synthetic.coupled_probes_table(placed, UniformField((3e-5, 0.0, 0.0)), np.arange(0.0, 360.0, 30.0), 2, rng).to_csv(
        directory / "probes.csv"
    )
    for name in ("a", "b", "c"):
        shutil.copy(ROOT / PAPER_PROBE_PATH, directory / f"{name}.yaml")
    # `mows lab ringdown recording`: a driver-like bag of one simulated ring-down in 1.5 mT along the axis.
    strong = load_scenario().replace(environment=Environment(sources=(UniformField((1.5e-3, 0.0, -4e-5)),)))
    record_cycles(directory / "recording", strong, (0.0,), 3)
    return directory


def test_the_documents_show_the_forms_this_file_must_cover():
    commands = documented_commands()
    assert {shlex.split(c)[2] for c in commands} == {"compare", "diagnose", "add", "report", "ringdown"}
    assert "mows lab add      sweep.csv --probe probe.yaml gravity thermal_drift" in commands
    assert any("transverse_gradient" in c for c in commands)


@pytest.mark.parametrize("command", documented_commands())
def test_a_documented_command_runs_verbatim(command, workdir, monkeypatch, capsys):
    monkeypatch.chdir(workdir)
    words = shlex.split(command)
    assert words[0] == "mows"
    assert main(words[1:]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    subcommand = words[2]
    if subcommand == "report":
        output = words[words.index("-o") + 1] if "-o" in words else "lab_report.html"
        assert (workdir / output).read_text().startswith("<!DOCTYPE html>")
        return
    assert "verdict:" in out
    if subcommand == "add" and "--auto" not in words:
        named = [
            w
            for w in words[3:]
            if not w.startswith("-") and w not in ("sweep.csv", "sweeps.csv") and not w.endswith((".yaml", ".py"))
        ]
        assert "eq6 + " + " + ".join(named) in out
