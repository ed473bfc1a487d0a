"""A supply pair wired the other way round (its current's sign reversed, as happens on any
bench) is found from the data, said, and calibrated with the sign found.

Requirement: the 36-ring-down simulated calibration table (Helmholtz and anti-Helmholtz sweeps
of the ``calibration`` scenario's probe) with either pair's currents negated calibrates to the
same constants as the table as written, within 4 standard uncertainties of the true ones, and
the report and the probe file say which pair was reversed. Taken as written, the reversed
gradient pair makes the fit fail: detection is what makes the table usable.
"""

import csv
import pathlib

import pytest
import yaml

from mows.cli.main import main
from mows.sim.scenario import load_scenario

TABLE = pathlib.Path(__file__).parent / "data" / "calibration_36.csv"
GRADIENT = ["--gradient-scenario", "calibration_gradient"]
CONSTANTS = ("f00_hz", "beta0_hz_per_t", "spring_nm_per_rad", "inertia_kgm2", "lever_m")


def reversed_table(path, gradient_wiring: float):
    """The table with the currents of one pair (gradient_wiring 0: Helmholtz, 1: gradient) negated."""
    with open(TABLE, newline="") as handle:
        rows = list(csv.DictReader(handle))
    for row in rows:
        if float(row["gradient_wiring"]) == gradient_wiring:
            row["supply_current_a"] = repr(-float(row["supply_current_a"]))
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return path


def calibrated(table, out, capsys, *options):
    status = main(["calibrate", str(table), *GRADIENT, "-o", str(out), *options])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    return yaml.safe_load(out.read_text())["calibration"], captured.out


@pytest.fixture(scope="module")
def as_written(tmp_path_factory):
    out = tmp_path_factory.mktemp("written") / "probe.yaml"
    assert main(["calibrate", str(TABLE), *GRADIENT, "-o", str(out)]) == 0
    return yaml.safe_load(out.read_text())["calibration"]


@pytest.mark.parametrize("pair, wiring, gradient_wiring", [("field", "helmholtz", 0.0), ("gradient", "gradient", 1.0)])
def test_a_reversed_pair_is_found_said_and_calibrated_with_its_sign(
    tmp_path, capsys, as_written, pair, wiring, gradient_wiring
):
    table = reversed_table(tmp_path / "reversed.csv", gradient_wiring)
    record, report = calibrated(table, tmp_path / "probe.yaml", capsys)
    assert record["polarity"] == {"helmholtz": 1, "gradient": 1, wiring: -1}
    assert f"polarity of the {wiring!r} wiring: reversed" in report
    truth = load_scenario("calibration").probe
    for name in CONSTANTS:
        value, std = record["constants"][name]["value"], record["constants"][name]["std"]
        assert value == pytest.approx(as_written["constants"][name]["value"], rel=1e-9), name
        assert abs(value - getattr(truth, name)) < 4.0 * std, (name, value, getattr(truth, name), std)
    # Told the sign, the command agrees; the wiring says so rather than the data.
    told, report = calibrated(table, tmp_path / "told.yaml", capsys, "--polarity", f"{pair}=-1")
    assert told["constants"]["lever_m"]["value"] == pytest.approx(record["constants"]["lever_m"]["value"], rel=1e-9)


def test_taken_as_written_the_reversed_gradient_pair_fails_the_fit(tmp_path, capsys):
    table = reversed_table(tmp_path / "reversed.csv", 1.0)
    status = main(["calibrate", str(table), *GRADIENT, "-o", str(tmp_path / "p.yaml"), "--polarity", "gradient=+1"])
    assert status == 2 and "cannot determine" in capsys.readouterr().err
    assert not (tmp_path / "p.yaml").exists()
