"""Every `mows` command with bad input: exit status 2, one line naming the file and the key or
row, no traceback, and nothing it read or did not create is touched."""

import os
import shutil
import subprocess
import sys

import pytest

from mows.cli.main import main
from mows.device.instruments.daq import PAPER_DEVICE_FILE
from mows.device.instruments.scpi import PAPER_SUPPLY_FILE
from mows.device.recording import bags
from mows.device.serial.emulator import DeviceEmulator
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

TABLE = os.path.join(os.path.dirname(__file__), os.pardir, "lab", "data", "demo_sweep.csv")
PROBE = "moment_am2: 0.89e-3\nmagnet_mass_kg: 7.2e-6\nspring_nm_per_rad: 1.36e-5\n"


def one_line_error(capsys, status, *words):
    """The command's stderr: one line, no traceback, holding every word."""
    err = capsys.readouterr().err
    assert status == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    for word in words:
        assert word in err, err
    return err


@pytest.fixture
def table(tmp_path):
    path = tmp_path / "sweep.csv"
    shutil.copy(TABLE, path)
    return path


@pytest.fixture
def bag(tmp_path):
    """A small valid bag (one excitation message)."""
    store = bags.typestore()
    message = store.types["std_msgs/msg/String"](data="hello")
    return bags.write_bag(tmp_path / "bag", [bags.BagMessage("/chatter", "std_msgs/msg/String", 1, message)])


def snapshot(*paths):
    """The bytes of every file under ``paths``."""
    files = {}
    for path in paths:
        walk = os.walk(path) if os.path.isdir(path) else [(os.path.dirname(path), [], [os.path.basename(path)])]
        for root, _, names in walk:
            for name in names:
                full = os.path.join(root, name)
                with open(full, "rb") as handle:
                    files[full] = handle.read()
    return files


# --- 1. nothing is overwritten ------------------------------------------------------------
@pytest.mark.parametrize("target", ["bag/bag.mcap", "bag/metadata.yaml", "bag"])
def test_fit_never_writes_its_csv_into_the_bag(bag, tmp_path, capsys, target):
    before = snapshot(bag)
    status = main(["fit", str(bag), "--csv", str(tmp_path / target), "--force"])
    one_line_error(capsys, status, "input")
    assert snapshot(bag) == before


def test_fit_of_the_mcap_file_never_writes_over_it(bag, capsys):
    mcap = bag / "bag.mcap"
    before = snapshot(bag)
    one_line_error(capsys, main(["fit", str(mcap), "--csv", str(mcap)]), "input", "bag.mcap")
    assert snapshot(bag) == before


def test_lab_report_never_writes_over_its_table(table, capsys):
    before = table.read_bytes()
    one_line_error(capsys, main(["lab", "report", str(table), "-o", str(table), "--force", "--no-cv"]), "input")
    assert table.read_bytes() == before


def test_lab_report_replaces_an_existing_page_only_with_force(table, tmp_path, capsys):
    page = tmp_path / "page.html"
    page.write_text("mine")
    one_line_error(capsys, main(["lab", "report", str(table), "-o", str(page), "--no-cv"]), "exists", "--force")
    assert page.read_text() == "mine"
    assert main(["lab", "report", str(table), "-o", str(page), "--no-cv", "--force"]) == 0
    assert page.read_text().startswith("<!DOCTYPE html>")
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no temporary left


def test_sim_out_never_replaces_an_existing_file(tmp_path, capsys):
    out = tmp_path / "cycles.npz"
    out.write_bytes(b"precious")
    one_line_error(capsys, main(["sim", "--out", str(out)]), "exists")
    assert out.read_bytes() == b"precious"


def test_the_emulator_refuses_a_link_path_that_exists(tmp_path):
    path = tmp_path / "device"
    path.write_bytes(b"precious")
    device = SimulatedDevice(load_scenario())
    with pytest.raises(FileExistsError, match="not this emulator's link"):
        DeviceEmulator(device, path).start()
    assert path.read_bytes() == b"precious" and not path.is_symlink()
    result = subprocess.run(
        [sys.executable, "-m", "mows.device.serial.emulator", "--link", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 2 and "Traceback" not in result.stderr and str(path) in result.stderr
    assert path.read_bytes() == b"precious"


def test_the_emulator_removes_only_its_own_link(tmp_path):
    path = tmp_path / "device"
    emulator = DeviceEmulator(SimulatedDevice(load_scenario()), path).start()
    try:
        assert path.is_symlink()
        path.unlink()
        path.write_bytes(b"someone else's")  # put there while the emulator runs
    finally:
        emulator.stop()
    assert path.read_bytes() == b"someone else's"


# --- 2. one error path ----------------------------------------------------------------------
SCENARIOS = {
    "unknown key": ("name: x\nbogus: 1\n", ["bogus", "allowed"]),
    "string value": ("excitation: {amplitude_a: big}\n", ["amplitude_a", "number"]),
    "over the cap": ("excitation: {amplitude_a: 1000}\n", ["1000 A", "cap"]),
    "not traceless": (
        "environment:\n  sources: [{type: linear_gradient, gradient_t_per_m: [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}]\n",
        ["traceless"],
    ),
    "1000 T": (
        "environment:\n  sources: [{type: uniform, field_t: [1000, 0, 0]}]\n",
        ["|field_t| = 1000 T is beyond any bench", "0 … 100 T"],
    ),
    "not YAML": ("excitation: [1\n", ["YAML", "line"]),
    "a quoted number": ('excitation: {amplitude_a: "2.0"}\n', ["excitation.amplitude_a = '2.0' is not a number"]),
    "NaN": ("excitation: {gap_s: .nan}\n", ["excitation.gap_s = nan must be a finite number"]),
    "a seed that is no integer": ("seed: 1.5\n", ["seed = 1.5 must be an integer"]),
    "magnets too close": (
        "probes:\n  - {pose: {magnet_position_m: [0, 0, 0]}}\n  - {pose: {magnet_position_m: [0, 5e-3, 0]}}\n",
        ["probes[1].pose.magnet_position_m = [0.0, 0.005, 0.0] is 5.00 mm from probes[0]", "7.78 mm apart"],
    ),
}


@pytest.mark.parametrize("case", SCENARIOS)
def test_a_bad_scenario_is_one_line(tmp_path, capsys, case):
    text, words = SCENARIOS[case]
    path = tmp_path / "scene.yaml"
    path.write_text(text)
    one_line_error(capsys, main(["sim", str(path)]), "scene.yaml", *words)
    assert path.read_text() == text


def test_a_thousand_tesla_is_refused_before_a_step(capsys, tmp_path):
    path = tmp_path / "strong.yaml"
    path.write_text(SCENARIOS["1000 T"][0])
    err = one_line_error(capsys, main(["sim", str(path)]))
    assert len(err) < 400  # one line that names the value, not θ printed as a 180-digit number


def test_fit_of_a_truncated_mcap_or_a_csv_is_one_line(bag, table, capsys):
    data = (bag / "bag.mcap").read_bytes()
    (bag / "bag.mcap").write_bytes(data[: len(data) // 2])
    one_line_error(capsys, main(["fit", str(bag / "bag.mcap")]), "bag.mcap")
    one_line_error(capsys, main(["fit", str(table)]), "sweep.csv")


PROBES = {
    "malformed YAML": ("moment_am2: [1\n", ["probe file", "YAML", "line 2"]),
    "a word for a number": ('f00_hz: "hundred"\n' + PROBE, ["f00_hz", "'hundred'", "not a number"]),
    "NaN": ("f00_hz: .nan\n" + PROBE, ["f00_hz", "nan", "finite"]),
    "a quoted number": ('lever_m: "1.9e-3"\n' + PROBE, ["lever_m = '1.9e-3' is not a number"]),
    "a key twice": (
        "moment_am2: 1e-3\n" + PROBE,
        ["not valid YAML: line 2, column 1: key 'moment_am2' is given twice"],
    ),
    "a directory": (None, ["probe file", "is a directory"]),
}


@pytest.mark.parametrize("case", PROBES)
def test_a_bad_probe_file_is_one_line_naming_the_key(table, tmp_path, capsys, case):
    text, words = PROBES[case]
    probe = tmp_path / "probe.yaml"
    if text is None:
        probe.mkdir()
    else:
        probe.write_text(text)
    err = one_line_error(
        capsys, main(["lab", "compare", str(table), "--probe", str(probe), "--no-cv"]), str(probe), *words
    )
    assert "inertia_kgm2" not in err  # not blamed on the inertia derived from the NaN


def test_numbers_in_our_files_are_read_as_yaml_1_2(table, tmp_path, capsys):
    """``1e-3`` (no dot) is a number, as YAML 1.2 and our docs write it: the probe file and the
    scenario that names it are read."""
    probe = tmp_path / "probe.yaml"
    probe.write_text("moment_am2: .89e-3\nmagnet_mass_kg: 7.2E-6\nf00_hz: 112.48\nspring_nm_per_rad: 136e-7\n")
    assert main(["lab", "compare", str(table), "--probe", str(probe), "--no-cv"]) == 0
    scene = tmp_path / "scene.yaml"
    scene.write_text("probe: probe.yaml\nnoise: {mains_t: 1e-8}\nexcitation: {ringdown_s: 2e-1, excite_s: 1e-1}\n")
    assert main(["sim", str(scene), "--fit"]) == 0
    assert "θ0 =" in capsys.readouterr().out


HARDWARE_FILES = {
    "supply: NaN voltage limit": (
        "--supply-file",
        ("voltage_limit_v: 10.0", "voltage_limit_v: .nan"),
        ["supply file", "voltage_limit_v = nan must be a finite number"],
    ),
    "supply: set_current not a format of the current": (
        "--supply-file",
        ('set_current: "CURR {:.4f}"', 'set_current: "CURR {:d}"'),
        ["commands.set_current = 'CURR {:d}' must hold one {} for the value, formatting a float"],
    ),
    "supply: channel no integer": (
        "--supply-file",
        ("channel: 1", "channel: 1.5"),
        ["channel = 1.5 is not an integer"],
    ),
    "device: both fluxgates on one input": (
        "--device",
        ("physical_channel: Dev1/ai1", "physical_channel: Dev1/ai0"),
        ["device file", "inputs[1].physical_channel = 'Dev1/ai0' is inputs[0]'s too"],
    ),
}


@pytest.mark.parametrize("case", HARDWARE_FILES)
def test_a_bad_bench_file_is_one_line(tmp_path, capsys, case):
    option, (good, bad), words = HARDWARE_FILES[case]
    shipped = PAPER_SUPPLY_FILE if option == "--supply-file" else PAPER_DEVICE_FILE
    assert good in shipped.read_text()
    path = tmp_path / "bench.yaml"
    path.write_text(shipped.read_text().replace(good, bad))
    one_line_error(capsys, main(["check-hardware", "--simulate", option, str(path)]), str(path), *words)


PLUGINS = {
    "raises": ("    raise RuntimeError('kaputt')\n", ["boom", "plugin.py", "RuntimeError", "kaputt"]),
    "NaN": ("    return {'frequency_hz': float('nan') * (k + 1)}\n", ["boom", "NaN", "finite"]),
    "not a dict": ("    return 3.0\n", ["boom", "float", "dict"]),
    "a string": ("    return {'frequency_hz': 'lots'}\n", ["boom", "'lots'"]),
}


@pytest.mark.parametrize("case", PLUGINS)
def test_a_broken_plugin_effect_is_one_line(table, tmp_path, capsys, case):
    body, words = PLUGINS[case]
    plugin = tmp_path / "plugin.py"
    plugin.write_text(
        "from mows.lab import effect\n\n"
        "@effect(name='boom', parameters={'k': (0.0, -1.0, 1.0, 'Hz')})\n"
        "def boom(rows, k):\n" + body
    )
    one_line_error(capsys, main(["lab", "diagnose", str(table), "--plugin", str(plugin), "--no-cv"]), *words)


def test_a_table_with_a_byte_order_mark_is_read(table, tmp_path, capsys):
    excel = tmp_path / "excel.csv"
    excel.write_bytes(b"\xef\xbb\xbf" + table.read_bytes())
    assert main(["lab", "compare", str(excel), "--no-cv"]) == 0
    assert "15 rows" in capsys.readouterr().out


def test_a_table_not_in_utf8_is_named(table, tmp_path, capsys):
    latin = tmp_path / "latin.csv"
    latin.write_bytes("théta,".encode("latin-1") + table.read_bytes())
    one_line_error(capsys, main(["lab", "compare", str(latin)]), "latin.csv", "UTF-8")


def test_a_directory_that_is_no_bag_is_named(tmp_path, capsys):
    folder = tmp_path / "folder"
    folder.mkdir()
    one_line_error(capsys, main(["lab", "compare", str(folder)]), "folder", "not a rosbag2 bag")
    one_line_error(capsys, main(["fit", str(folder)]), "folder", "not a rosbag2 bag")


def test_debug_shows_the_traceback(tmp_path):
    path = tmp_path / "scene.yaml"
    path.write_text(SCENARIOS["unknown key"][0])
    with pytest.raises(ValueError, match="bogus"):
        main(["sim", str(path), "--debug"])


@pytest.mark.parametrize("angle, same", [(725.0, "5°"), (-30.0, "330°")])
def test_a_wrapped_angle_gets_a_note(table, tmp_path, capsys, angle, same):
    lines = table.read_text().splitlines()
    cells = lines[1].split(",")
    cells[0] = repr(angle)
    wrapped = tmp_path / "wrapped.csv"
    wrapped.write_text("\n".join([lines[0], ",".join(cells)] + lines[2:]) + "\n")
    assert main(["lab", "compare", str(wrapped), "--no-cv"]) == 0
    out = capsys.readouterr().out
    assert "note: theta0_deg outside [0, 360) in row 1 " in out and f"is {same}" in out
