"""docs/model_lab.md's walkthrough "When the catalog has no answer" runs as printed.

Requirement: the commands of the section, read from the document, run verbatim in a directory
holding what they name, and print what the section shows: every line of its output blocks
appears in the command's output, its numbers to the digits printed (an ellipsis stands for what
the section leaves out). The files are made as a user would have them: the bag ``recording`` of
the simulated session (12 orientations × 2 sweeps, seed 0: the magnet loses 0.12 %/K of its
moment while the probe warms 0.3 K/s in 0.43 mT, every ring-down from the stop), the logger's
``temperature.csv`` (device time, kelvin, every second), the user's ``probe.yaml`` (which knows
nothing of the magnet's temperature), the scene as ``scenario.yaml``, and the section's own
plugin files.
"""

import contextlib
import csv
import io
import math
import pathlib
import re
import shlex

import numpy as np
import pytest

from lab.test_cli_documented import documented_plugin
from lab.test_recorded_path import ANGLES_DEG, SCENES, SEED
from mows.cli.main import main
from recorded_bags import record_cycles

pytestmark = pytest.mark.slow

ROOT = pathlib.Path(__file__).resolve().parents[2]
SECTION = "## When the catalog has no answer"
NUMBER = r"[-+−]?\d+(?:\.\d+)?(?:e[-+]?\d+)?"


def walkthrough() -> list[tuple[str, list[str]]]:
    """(command, the output lines the section shows for it), in order: a fenced block's lines
    that start with ``mows`` are commands, the others the output of the command before them."""
    text = (ROOT / "docs" / "model_lab.md").read_text()
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    steps: list[tuple[str, list[str]]] = []
    for language, block in re.findall(r"```(\w*)\n(.*?)```", section, flags=re.S):
        if language == "python":
            continue
        for line in block.splitlines():
            if line.startswith("mows "):
                steps.append((re.sub(r"\s+#.*", "", line).strip(), []))
            elif line.strip():
                steps[-1][1].append(line)
    return steps


def _pattern(line: str) -> tuple[re.Pattern, list[str]]:
    """A regex of a printed line (numbers captured, an ellipsis for anything) and its numbers."""
    parts, numbers = [], []
    for piece in re.split(f"({NUMBER}|…)", line.strip()):
        if piece == "…":
            parts.append(".*?")
        elif re.fullmatch(NUMBER, piece):
            parts.append(f"({NUMBER})")
            numbers.append(piece)
        else:
            parts.append(r"\s+".join(re.escape(word) for word in piece.split()) + (r"\s*" if piece.strip() else ""))
    return re.compile(r"\s*".join(part for part in parts if part)), numbers


def _value(text: str) -> float:
    return float(text.replace("−", "-"))


def printed(expected: str, output: str) -> bool:
    """Whether ``expected`` appears in ``output`` (one line of it, or across its wrapped lines),
    each number equal to the digits printed."""
    pattern, numbers = _pattern(expected)
    flat = " ".join(output.split())
    for match in pattern.finditer(flat):
        digits = [len(n.split(".")[1].split("e")[0]) if "." in n else 0 for n in numbers]
        if all(
            math.isclose(_value(found), _value(shown), abs_tol=0.5 * 10.0**-places * (1 + 1e-9))
            or _value(found) == pytest.approx(_value(shown), rel=1e-12)
            for found, shown, places in zip(match.groups(), numbers, digits)
        ):
            return True
    return False


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    """The directory the section's commands run in (module docstring)."""
    directory = tmp_path_factory.mktemp("walkthrough")
    scenario = SCENES["moment_temperature"]()
    _, records = record_cycles(directory / "recording", scenario, ANGLES_DEG, SEED)
    last = records[-1]
    end_s = (last.block.samples.first_sample_index + len(last.samples_t)) / last.sample_rate_hz
    with open(directory / "temperature.csv", "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["t_s", "temperature_k"])
        for t_s in np.arange(0.0, math.ceil(end_s) + 1.0):
            writer.writerow([f"{t_s:g}", repr(float(scenario.environment.temperature_at(t_s)))])
    scenario.probe.replace(moment_temp_coeff_per_k=0.0).to_yaml(directory / "probe.yaml")
    scenario.to_yaml(directory / "scenario.yaml")
    (directory / "moment_temperature.py").write_text(documented_plugin("moment_temperature"))
    return directory


def test_the_section_shows_commands_and_what_they_print():
    steps = walkthrough()
    assert [command.split()[:3] for command, _ in steps][:1] == [["mows", "fit", "recording"]]
    assert sum(len(lines) for _, lines in steps) >= 8


def test_the_walkthrough_prints_what_the_docs_show(session, monkeypatch):
    monkeypatch.chdir(session)
    for command, expected in walkthrough():
        out = io.StringIO()
        with contextlib.redirect_stdout(out):
            status = main(shlex.split(command)[1:])
        assert status == 0, (command, out.getvalue())
        missing = [line for line in expected if not printed(line, out.getvalue())]
        assert not missing, (command, missing, out.getvalue())
