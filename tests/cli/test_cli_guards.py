"""Nothing destroys data, nothing crashes, nothing implausible passes.

Requirement: every bad input, misplaced output or interrupt ends a ``mows`` command (and the
device emulator) with exactly one line on stderr, no traceback, the exit status of the
convention (0 done, 1 a bug, 2 bad input or usage, 130 interrupted; docs/cli.md), and every
file in the working directory byte for byte as before (no partial output, no temporary left).
"""

import csv
import hashlib
import json
import os
import pathlib
import shutil
import signal
import stat
import subprocess
import sys

import numpy as np
import pytest

from mows.cli import calibrate as calibrate_cli
from mows.cli import sim as sim_cli
from mows.cli.inputs import report_errors
from mows.cli.main import main
from mows.device import instruments as hardware_dir
from mows.device.serial import emulator
from mows.physics.probe import PAPER_PROBE
from mows.records.files import OutputRefused, recover, writing
from mows.sim.scenario import SCENARIO_DIR, load_scenario
from recorded_bags import record_cycles

HERE = pathlib.Path(__file__).parents[1]  # tests/
CALIBRATION_TABLE = HERE / "estimate" / "data" / "calibration_36.csv"
SWEEP_TABLE = HERE / "lab" / "data" / "demo_sweep.csv"
HARDWARE = pathlib.Path(hardware_dir.__file__).parent / "hardware"


def rewrite(source, target, change) -> None:
    """``source``'s CSV rows, each passed through ``change(index, row)``, written to ``target``."""
    with open(source, newline="") as handle:
        rows = list(csv.DictReader(handle))
    for i, row in enumerate(rows):
        change(i, row)
    with open(target, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows[:1] if target.name.endswith("one_row.csv") else rows)


def scale(column, factor):
    return lambda i, row: row.update({column: repr(float(row[column]) * factor)})


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    """A directory of inputs, good and bad, and of things an output must never replace."""
    d = tmp_path_factory.mktemp("guards")
    shutil.copy(CALIBRATION_TABLE, d / "cal.csv")
    shutil.copy(SWEEP_TABLE, d / "sweep.csv")
    rewrite(CALIBRATION_TABLE, d / "cal_ma.csv", scale("supply_current_a", 1e3))
    rewrite(CALIBRATION_TABLE, d / "cal_ka.csv", scale("supply_current_a", 1e-3))
    rewrite(CALIBRATION_TABLE, d / "cal_khz.csv", scale("f_hz", 1e-3))
    rewrite(CALIBRATION_TABLE, d / "cal_huge_f.csv", lambda i, row: row.update(f_hz="1e300"))
    rewrite(CALIBRATION_TABLE, d / "cal_nan_current.csv", lambda i, row: i == 2 and row.update(supply_current_a="nan"))
    rewrite(CALIBRATION_TABLE, d / "one_row.csv", lambda i, row: None)
    rewrite(CALIBRATION_TABLE, d / "cal_growing.csv", lambda i, row: i == 4 and row.update(damping_per_s="-2"))
    rewrite(CALIBRATION_TABLE, d / "cal_wiring_2.csv", lambda i, row: i == 4 and row.update(gradient_wiring="2"))
    rewrite(CALIBRATION_TABLE, d / "cal_huge_swing.csv", lambda i, row: i == 4 and row.update(amplitude_deg="1e6"))
    (d / "empty.csv").write_text("")
    rewrite(SWEEP_TABLE, d / "sweep_khz.csv", scale("f_hz", 1e-3))
    rewrite(SWEEP_TABLE, d / "sweep_field_in_ut.csv", scale("ref_bx_t", 1e6))
    mt_as_t = ("ref_bx_t", "ref_by_t", "ref_bz_t", "ref_gxx_t_per_m", "ref_gxy_t_per_m", "ref_gyy_t_per_m")
    rewrite(SWEEP_TABLE, d / "sweep_reference_in_mt.csv", lambda i, row: [scale(c, 1e3)(i, row) for c in mt_as_t])
    rewrite(SWEEP_TABLE, d / "sweep_huge_std.csv", lambda i, row: row.update(f_std_hz="1e30"))
    rewrite(SWEEP_TABLE, d / "sweep_probe_words.csv", lambda i, row: row.update(probe="abc"[i % 3]))
    (d / "sweep_semicolons.csv").write_text(SWEEP_TABLE.read_text().replace(",", ";"))
    rewrite(SWEEP_TABLE, d / "sweep_one_row.csv", lambda i, row: None)
    rewrite(SWEEP_TABLE, d / "sweep_no_reference.csv", lambda i, row: [row.pop(k) for k in list(row) if "ref_" in k])
    PAPER_PROBE.to_yaml(d / "probe.yaml")
    calibration = (SCENARIO_DIR / "calibration.yaml").read_text()
    (d / "unipolar.yaml").write_text(
        calibration.replace("  resolution_a: 1.0e-4", "  resolution_a: 1.0e-4\n  polarity: unipolar")
    )
    text = (d / "probe.yaml").read_text()
    (d / "probe_1000x.yaml").write_text(text.replace("moment_am2: 0.00089", "moment_am2: 0.89"))
    (d / "probe_two_stops.yaml").write_text(text + "theta_stop_deg: 24.0\n")
    record_cycles(d / "bag", load_scenario(), (0.0,), 3)
    record_cycles(d / "empty_bag", load_scenario(), (), 3)
    (d / "existing.yaml").write_text("kept\n")
    (d / "mount.urdf").write_text('<robot name="m"><link name="a"/></robot>\n')
    (d / "mount_not_xml.urdf").write_text("robot: {}\n")
    (d / "exits.py").write_text("import sys\n\nsys.exit(0)\n")
    (d / "raises_exit.py").write_text("raise SystemExit(3)\n")
    (d / "plugin.py").write_text(PLUGIN.format(body="return {'frequency_hz': 0.0 * k}"))
    (d / "plugin_exits.py").write_text(PLUGIN.format(body="sys.exit(1)"))
    (d / "magic.mcap").write_bytes(b"\x89MCAP0\r\n")  # MCAP's magic and nothing else
    shutil.copytree(d / "bag", d / "latin_bag")
    metadata = d / "latin_bag" / "metadata.yaml"
    metadata.write_bytes(b"# caf\xe9\n" + metadata.read_bytes())  # Latin-1, not UTF-8
    (d / "deep.yaml").write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    implausible_inputs(d)
    (d / "huge_cell.csv").write_text(SWEEP_TABLE.read_text() + '"' + "1" * 200_000 + '"\n')
    # Files a command reads without naming them: a scenario's probe file and its extends: base.
    PAPER_PROBE.to_yaml(d / "scene_probe.yaml")
    (d / "scene.yaml").write_text("extends: paper_largest_spacing\nprobe: scene_probe.yaml\n")
    (d / "scene_base.yaml").write_text("extends: calibration_gradient\n")
    (d / "scene_child.yaml").write_text("extends: scene_base.yaml\n")
    os.mkfifo(d / "fifo")
    if os.geteuid() == 0:  # only root makes device files: the test of one needs it
        os.mknod(d / "null", 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    return d


#: A plugin of one effect whose function does ``body``.
PLUGIN = """import sys

from mows.lab import effect


@effect(name="boom", parameters={{"k": (0.0, -1.0, 1.0, "Hz")}})
def boom(rows, k):
    {body}
"""


def implausible_inputs(d: pathlib.Path) -> None:
    """Tables, probe files and hardware files with numbers no bench produces, or seldom does."""
    rewrite(SWEEP_TABLE, d / "sweep_temperature_in_c.csv", lambda i, row: row.update(temperature_k="21.5"))
    rewrite(SWEEP_TABLE, d / "sweep_coil_2000_a.csv", lambda i, row: row.update(coil_current_a="2000"))
    rewrite(SWEEP_TABLE, d / "sweep_duration_in_ms.csv", scale("duration_s", 1e3))
    rewrite(SWEEP_TABLE, d / "sweep_amplitude_in_rad.csv", scale("amplitude_deg", np.pi / 180))
    rewrite(SWEEP_TABLE, d / "sweep_theta_in_rad.csv", scale("theta0_deg", np.pi / 180))
    rewrite(SWEEP_TABLE, d / "sweep_negative_t.csv", lambda i, row: row.update(t_s=repr(-1.0 - i)))
    rewrite(SWEEP_TABLE, d / "sweep_one_orientation.csv", lambda i, row: row.update(theta0_deg="30"))
    with open(SWEEP_TABLE) as handle:
        header, first = handle.readline(), handle.readline()
    (d / "sweep_20_copies.csv").write_text(header + first * 20)
    (d / "sweep_two_rows.csv").write_text("".join(SWEEP_TABLE.read_text().splitlines(keepends=True)[:3]))
    rewrite(SWEEP_TABLE, d / "sweep_std_1e-30.csv", lambda i, row: row.update(f_std_hz="1e-30"))
    rewrite(SWEEP_TABLE, d / "sweep_probe_minus_1.csv", lambda i, row: row.update(probe="-1"))
    text = (d / "probe.yaml").read_text()
    (d / "probe_7_kg.yaml").write_text(text.replace("magnet_mass_kg: 7.2e-06", "magnet_mass_kg: 7.2"))
    assert "reference_temperature_k: 293.15" in text
    (d / "probe_20_k.yaml").write_text(text.replace("reference_temperature_k: 293.15", "reference_temperature_k: 20.0"))
    supply = (HARDWARE / "rs_ngm202.yaml").read_text()
    for name, old, new in [
        ("slow_slew", "slew_a_per_s: 2.0", "slew_a_per_s: 1.0e-6"),
        ("long_settle", "settle_s: 0.1", "settle_s: 1.0e5"),
        ("long_timeout", "timeout_s: 2.0", "timeout_s: 1.0e5"),
    ]:
        assert old in supply
        (d / f"supply_{name}.yaml").write_text(supply.replace(old, new))
    scene = "extends: paper_largest_spacing\nsensors:\n  positions_m: {}\n"
    (d / "scene_one_spot.yaml").write_text(scene.format("[[0.06, 0.0, 0.0], [0.06, 0.0, 0.0]]"))
    (d / "scene_at_magnet.yaml").write_text(scene.format("[[0.0, 0.0, 0.0], [0.03, 0.0, 0.0]]"))
    (d / "scene_coils_1_mm.yaml").write_text(
        "extends: paper_largest_spacing\nsetup: {preset: largest_spacing, distance_m: 0.001}\n"
    )
    (d / "scene_10_t.yaml").write_text(
        "extends: paper_largest_spacing\nenvironment:\n  sources: [{type: uniform, field_t: [10.0, 0, 0]}]\n"
    )
    (d / "scene_probe_and_probes.yaml").write_text(
        "extends: paper_largest_spacing\nprobe: paper\nprobes:\n  - probe: paper\n"
    )
    card = (HARDWARE / "ni_pcie6363.yaml").read_text()
    (d / "card_long_lead.yaml").write_text(card.replace("output_lead_s: 2.0", "output_lead_s: 1.0e6"))


def snapshot(directory: pathlib.Path) -> dict:
    """Every path under ``directory``: a regular file's hash, anything else its type."""
    state = {}
    for path in sorted(directory.rglob("*")):
        mode = path.lstat().st_mode
        if stat.S_ISREG(mode):
            state[path] = hashlib.sha256(path.read_bytes()).hexdigest()
        else:
            state[path] = stat.S_IFMT(mode)
    return state


CAL = ["calibrate", "{d}/cal.csv", "--gradient-scenario", "calibration_gradient"]
#: (id, arguments, exit status, words the one line must hold); "{d}" is the work directory.
CASES = [
    # outputs: never over an input, an existing file, a device or a FIFO; several all or none
    ("calibrate-over-its-table", [*CAL, "-o", "{d}/cal.csv", "--force"], 2, ["input"]),
    (
        "calibrate-over-its-probe",
        ["calibrate", "--simulate", "--probe", "{d}/probe.yaml", "-o", "{d}/probe.yaml"],
        2,
        ["input"],
    ),
    ("calibrate-two-outputs-one-file", [*CAL, "-o", "{d}/x.yaml", "--table", "{d}/x.yaml"], 2, ["one file"]),
    (
        "calibrate-output-fails-no-table",
        [*CAL, "-o", "{d}/nodir/p.yaml", "--table", "{d}/t.csv"],
        2,
        ["does not exist"],
    ),
    ("calibrate-existing", [*CAL, "-o", "{d}/existing.yaml"], 2, ["exists", "--force"]),
    ("calibrate-force-device", [*CAL, "-o", "{d}/null", "--force"], 2, ["character device"]),
    ("sim-output-under-a-file", ["sim", "--out", "{d}/existing.yaml/x.npz"], 2, ["{d}/existing.yaml is a file"]),
    (
        "lab-report-output-under-a-file",
        ["lab", "report", "{d}/sweep.csv", "-o", "{d}/existing.yaml/r.html"],
        2,
        ["output {d}/existing.yaml/r.html: directory {d}/existing.yaml is a file"],
    ),
    ("fit-force-fifo", ["fit", "{d}/bag", "--csv", "{d}/fifo", "--force"], 2, ["FIFO"]),
    ("sim-force-fifo", ["sim", "--out", "{d}/fifo", "--force"], 2, ["FIFO"]),
    ("lab-report-force-fifo", ["lab", "report", "{d}/sweep.csv", "-o", "{d}/fifo", "--force"], 2, ["FIFO"]),
    # ... nor inside a bag folder, the bag named by its folder or its .mcap file, nor over --mount
    (
        "fit-csv-over-the-bag-s-metadata",
        ["fit", "{d}/bag/bag.mcap", "--csv", "{d}/bag/metadata.yaml", "--force"],
        2,
        ["inside the bag {d}/bag"],
    ),
    (
        "viz-over-the-bag-s-metadata",
        ["viz", "{d}/bag/bag.mcap", "-o", "{d}/bag/metadata.yaml", "--force"],
        2,
        ["inside the bag {d}/bag"],
    ),
    (
        "viz-over-its-mount",
        ["viz", "{d}/bag", "--mount", "{d}/mount.urdf", "-o", "{d}/mount.urdf", "--force"],
        2,
        ["input", "mount.urdf"],
    ),
    ("fit-csv-inside-the-bag", ["fit", "{d}/bag/bag.mcap", "--csv", "{d}/bag/fits.csv"], 2, ["inside the bag {d}/bag"]),
    ("viz-inside-the-bag", ["viz", "{d}/bag/bag.mcap", "-o", "{d}/bag/new.mcap"], 2, ["inside the bag {d}/bag"]),
    ("viz-figures-in-the-bag", ["viz", "{d}/bag/bag.mcap", "--figures", "{d}/bag"], 2, ["inside the bag {d}/bag"]),
    (
        "viz-figures-under-the-bag",
        ["viz", "{d}/bag", "--figures", "{d}/bag/figures"],
        2,
        ["input of this command ({d}/bag)"],
    ),
    (
        "lab-report-inside-a-bag",
        ["lab", "report", "{d}/sweep.csv", "-o", "{d}/bag/r.html"],
        2,
        ["inside the bag {d}/bag"],
    ),
    (
        "viz-mount-not-xml",
        ["viz", "{d}/bag", "--mount", "{d}/mount_not_xml.urdf", "-o", "{d}/v.mcap"],
        2,
        ["mount {d}/mount_not_xml.urdf", "not a URDF"],
    ),
    (
        "lab-report-over-its-plugin",
        ["lab", "report", "{d}/sweep.csv", "--plugin", "{d}/plugin.py", "-o", "{d}/plugin.py", "--force"],
        2,
        ["input", "plugin.py"],
    ),
    (
        "lab-report-over-its-probe",
        ["lab", "report", "{d}/sweep.csv", "--probe", "{d}/probe.yaml", "-o", "{d}/probe.yaml", "--force"],
        2,
        ["input", "probe.yaml"],
    ),
    (
        "lab-plugin-raises-system-exit",
        ["lab", "compare", "{d}/sweep.csv", "--plugin", "{d}/raises_exit.py"],
        2,
        ["{d}/raises_exit.py:1 tried to end the command (sys.exit(3))"],
    ),
    (
        "lab-plugin-effect-that-exits",
        ["lab", "diagnose", "{d}/sweep.csv", "--plugin", "{d}/plugin_exits.py", "--no-cv"],
        2,
        ["{d}/plugin_exits.py:8 tried to end the command (sys.exit(1))"],
    ),
    (
        "lab-plugin-that-exits",
        ["lab", "compare", "{d}/sweep.csv", "--plugin", "{d}/exits.py"],
        2,
        ["{d}/exits.py:3 tried to end the command (sys.exit(0))"],
    ),
    # numbers no bench produces: refused, naming the value and its range
    (
        "lab-coil-current-2000-a",
        ["lab", "compare", "{d}/sweep_coil_2000_a.csv"],
        2,
        ["coil_current_a", "0 … 100 A", "mA given as A?", "rows 1, 2, 3"],
    ),
    ("lab-f-std-1e-30", ["lab", "compare", "{d}/sweep_std_1e-30.csv"], 2, ["f_std_hz", "at least 1e-10 of f_hz"]),
    ("lab-probe-id-minus-1", ["lab", "compare", "{d}/sweep_probe_minus_1.csv"], 2, ["probe", "0 or more"]),
    ("lab-20-identical-rows", ["lab", "compare", "{d}/sweep_20_copies.csv"], 2, ["all 20 rows are one measurement"]),
    ("lab-two-rows", ["lab", "compare", "{d}/sweep_two_rows.csv"], 2, ["2 rows", "measure at least 3"]),
    (
        "lab-one-orientation",
        ["lab", "compare", "{d}/sweep_one_orientation.csv"],
        2,
        ["θ0 = 30°", "several orientations"],
    ),
    (
        "lab-magnet-7-kg",
        ["lab", "compare", "{d}/sweep.csv", "--probe", "{d}/probe_7_kg.yaml"],
        2,
        ["probe file {d}/probe_7_kg.yaml", "magnet_mass_kg = 7.2 kg", "grams given as kg?"],
    ),
    (
        "lab-magnet-position-nan",
        ["lab", "compare", "{d}/sweep.csv", "--magnet-position", "nan", "0", "0"],
        2,
        ["--magnet-position", "finite"],
    ),
    ("sim-amplitude-0", ["sim", "--amplitude-a", "0"], 2, ["--amplitude-a 0", "no current"]),
    ("sim-fluxgates-at-one-spot", ["sim", "{d}/scene_one_spot.yaml"], 2, ["scene_one_spot.yaml", "at one spot"]),
    ("sim-fluxgate-at-the-magnet", ["sim", "{d}/scene_at_magnet.yaml"], 2, ["positions_m[0]", "at the magnet"]),
    ("sim-probe-and-probes", ["sim", "{d}/scene_probe_and_probes.yaml"], 2, ["both probe:", "give one of them"]),
    (
        "sim-coils-1-mm-from-the-probe",
        ["sim", "{d}/scene_coils_1_mm.yaml"],
        2,
        ["scene_coils_1_mm.yaml", "distance_m = 0.001 m puts the probe inside the coil"],
    ),
    ("sim-amplitude-2000", ["sim", "--amplitude-a", "2000"], 2, ["--amplitude-a = 2000 A", "beyond any bench"]),
    (
        "check-hardware-supply-step-0",
        ["check-hardware", "--simulate", "--supply-step-a", "0"],
        2,
        ["--supply-step-a 0 A", "test nothing"],
    ),
    (
        "check-hardware-at-resonance",
        ["check-hardware", "--simulate", "--frequency-hz", "112.48"],
        2,
        ["--frequency-hz 112.48 Hz", "resonance"],
    ),
    (
        "check-hardware-10-khz",
        ["check-hardware", "--simulate", "--frequency-hz", "10000"],
        2,
        ["--frequency-hz 10000 Hz is above 2000 Hz", "samples a period"],
    ),
    *[
        (f"check-hardware-{name}", ["check-hardware", "--simulate", option, f"{{d}}/{file}"], 2, words)
        for name, option, file, words in (
            ("slew-1e-6", "--supply-file", "supply_slow_slew.yaml", ["slew_a_per_s = 1e-06 A/s", "0.01 … 1e+07"]),
            ("settle-1e5", "--supply-file", "supply_long_settle.yaml", ["settle_s = 100000 s", "0 … 60 s"]),
            ("timeout-1e5", "--supply-file", "supply_long_timeout.yaml", ["timeout_s = 100000 s", "0.001 … 600 s"]),
            ("lead-1e6", "--device", "card_long_lead.yaml", ["output_lead_s = 1e+06 s", "0.001 … 10 s"]),
        )
    ],
    # malformed files: one line naming the file and the problem
    *[
        (f"{argv[0]}-{argv[1] if argv[0] == 'lab' else ''}-magic-only", argv, 2, ["magic.mcap cannot be read as a bag"])
        for argv in (
            ["fit", "{d}/magic.mcap"],
            ["map", "{d}/magic.mcap"],
            ["viz", "{d}/magic.mcap", "-o", "{d}/v.mcap"],
            ["lab", "compare", "{d}/magic.mcap"],
            ["lab", "report", "{d}/magic.mcap", "-o", "{d}/r.html"],
            ["lab", "ringdown", "{d}/magic.mcap"],
            ["calibrate", "{d}/magic.mcap", "-o", "{d}/p.yaml"],
        )
    ],
    ("fit-metadata-not-utf8", ["fit", "{d}/latin_bag"], 2, ["{d}/latin_bag/metadata.yaml is not UTF-8"]),
    ("sim-yaml-5000-deep", ["sim", "{d}/deep.yaml"], 2, ["scenario {d}/deep.yaml", "nested deeper"]),
    (
        "lab-probe-yaml-5000-deep",
        ["lab", "compare", "{d}/sweep.csv", "--probe", "{d}/deep.yaml"],
        2,
        ["probe file {d}/deep.yaml", "nested deeper"],
    ),
    ("lab-csv-cell-over-128-kib", ["lab", "compare", "{d}/huge_cell.csv"], 2, ["{d}/huge_cell.csv: line", "field"]),
    ("lab-compare-a-fifo", ["lab", "compare", "{d}/fifo"], 2, ["{d}/fifo is a FIFO, not a file"]),
    ("calibrate-a-fifo", ["calibrate", "{d}/fifo", "-o", "{d}/p.yaml"], 2, ["{d}/fifo is a FIFO, not a file"]),
    *[
        (f"{name}-a-{kind}", [*argv, f"{{d}}/{kind}", *more], 2, [f"{{d}}/{kind} is a {what}, not a file"])
        for name, argv, more in (
            ("sim-scenario", ["sim"], []),
            ("lab-probe", ["lab", "compare", "{d}/sweep.csv", "--probe"], []),
            ("lab-plugin", ["lab", "compare", "{d}/sweep.csv", "--plugin"], []),
            ("lab-reference", ["lab", "compare", "{d}/sweep_no_reference.csv", "--reference"], []),
            ("fit-bag", ["fit"], []),
            ("viz-mount", ["viz", "{d}/bag", "--mount"], ["-o", "{d}/v.mcap"]),
            ("check-hardware-supply-file", ["check-hardware", "--simulate", "--supply-file"], []),
            ("check-hardware-device", ["check-hardware", "--simulate", "--device"], []),
            ("calibrate-scenario", ["calibrate", "--simulate", "-o", "{d}/p.yaml", "--scenario"], []),
        )
        for kind, what in (("fifo", "FIFO"), ("null", "character device"))
    ],
    # ... nor over a file the command read without naming it (a scenario's probe: or extends:)
    (
        "sim-over-its-scenario-s-probe",
        ["sim", "{d}/scene.yaml", "--out", "{d}/scene_probe.yaml", "--force"],
        2,
        ["input", "scene_probe.yaml"],
    ),
    (
        "sim-over-its-scenario-s-base",
        ["sim", "{d}/scene_child.yaml", "--out", "{d}/scene_base.yaml", "--force"],
        2,
        ["input", "scene_base.yaml"],
    ),
    (
        "calibrate-over-its-scenario-s-probe",
        ["calibrate", "--simulate", "--scenario", "{d}/scene.yaml", "-o", "{d}/scene_probe.yaml", "--force"],
        2,
        ["input", "scene_probe.yaml"],
    ),
    (
        "calibrate-table-over-its-gradient-scenario-s-base",
        [
            *CAL[:2],
            "--gradient-scenario",
            "{d}/scene_child.yaml",
            "-o",
            "{d}/p.yaml",
            "--table",
            "{d}/scene_base.yaml",
            "--force",
        ],
        2,
        ["input", "scene_base.yaml"],
    ),
    (
        "lab-report-over-its-reference-s-probe",
        [
            "lab",
            "report",
            "{d}/sweep_no_reference.csv",
            "--reference",
            "{d}/scene.yaml",
            "-o",
            "{d}/scene_probe.yaml",
            "--force",
        ],
        2,
        ["input", "scene_probe.yaml"],
    ),
    (
        "lab-report-over-its-reference-s-base",
        [
            "lab",
            "report",
            "{d}/sweep_no_reference.csv",
            "--reference",
            "{d}/scene_child.yaml",
            "-o",
            "{d}/scene_base.yaml",
            "--force",
        ],
        2,
        ["input", "scene_base.yaml"],
    ),
    (
        "calibrate-over-its-scenario-s-base",
        ["calibrate", "--simulate", "--scenario", "{d}/scene_child.yaml", "-o", "{d}/scene_base.yaml", "--force"],
        2,
        ["input", "scene_base.yaml"],
    ),
    # calibration: currents beyond the cap, units, non-finite values, too little data
    (
        "calibrate-500-a",
        ["calibrate", "--simulate", "-o", "{d}/p.yaml", "--currents-a", "0", "1", "500"],
        2,
        ["500", "cap"],
    ),
    (
        "calibrate-negative-on-a-unipolar-supply",
        ["calibrate", "--simulate", "--scenario", "{d}/unipolar.yaml", "-o", "{d}/p.yaml", "--currents-a", "1", "-1"],
        2,
        ["-1 A", "0 … +2 A", "θ0 + 180°"],
    ),
    (
        "check-hardware-negative-step-on-the-ngm202",
        ["check-hardware", "--simulate", "--supply-step-a", "-0.1"],
        2,
        ["-0.1 A", "0 … +2 A (unipolar)"],
    ),
    ("calibrate-table-in-ma", ["calibrate", "{d}/cal_ma.csv", "-o", "{d}/p.yaml"], 2, ["cap", "mA"]),
    (
        "calibrate-table-in-ka",
        [*CAL[:1], "{d}/cal_ka.csv", *CAL[2:], "-o", "{d}/p.yaml"],
        2,
        ["implausible", "spring_nm_per_rad"],
    ),
    ("calibrate-f-in-khz", ["calibrate", "{d}/cal_khz.csv", "-o", "{d}/p.yaml"], 2, ["f00", "kHz"]),
    ("calibrate-f-1e300", ["calibrate", "{d}/cal_huge_f.csv", "-o", "{d}/p.yaml"], 2, ["f00"]),
    (
        "calibrate-nan-current",
        ["calibrate", "{d}/cal_nan_current.csv", "-o", "{d}/p.yaml"],
        2,
        ["supply_current_a", "row 3"],
    ),
    ("calibrate-one-row", ["calibrate", "{d}/one_row.csv", "-o", "{d}/p.yaml"], 2, ["too few"]),
    ("calibrate-empty-table", ["calibrate", "{d}/empty.csv", "-o", "{d}/p.yaml"], 2, ["empty.csv is empty"]),
    (
        "calibrate-growing-ring-down",
        [*CAL[:1], "{d}/cal_growing.csv", *CAL[2:], "-o", "{d}/p.yaml"],
        2,
        ["damping_per_s", "≥ 0", "row 5"],
    ),
    (
        "calibrate-wiring-2",
        [*CAL[:1], "{d}/cal_wiring_2.csv", *CAL[2:], "-o", "{d}/p.yaml"],
        2,
        ["gradient_wiring", "row 5"],
    ),
    (
        "calibrate-swing-1e6-deg",
        [*CAL[:1], "{d}/cal_huge_swing.csv", *CAL[2:], "-o", "{d}/p.yaml"],
        2,
        ["amplitude_deg", "180°", "row 5"],
    ),
    (
        "calibrate-table-and-simulate",
        ["calibrate", "{d}/cal.csv", "--simulate", "-o", "{d}/p.yaml"],
        2,
        ["two sources"],
    ),
    (
        "calibrate-simulation-option-unused",
        [*CAL, "-o", "{d}/p.yaml", "--repeats", "3", "--seed", "1"],
        2,
        ["--repeats, --seed shape only --simulate"],
    ),
    (
        "calibrate-bag-options-with-a-table",
        [*CAL, "-o", "{d}/p.yaml", "--supply-topic", "/s", "--coil-off-skip-s", "0.01"],
        2,
        ["--supply-topic, --coil-off-skip-s shape only a BAG's calibration", "give a BAG"],
    ),
    (
        "calibrate-bag-option-with-simulate",
        ["calibrate", "--simulate", "-o", "{d}/p.yaml", "--paper-model"],
        2,
        ["--paper-model shapes only a BAG's calibration"],
    ),
    ("calibrate-repeats-0", ["calibrate", "--simulate", "-o", "{d}/p.yaml", "--repeats", "0"], 2, ["--repeats"]),
    ("calibrate-bad-polarity", [*CAL, "-o", "{d}/p.yaml", "--polarity", "gradient=2"], 2, ["--polarity"]),
    ("calibrate-nan-environment", [*CAL, "-o", "{d}/p.yaml", "--environment-field-t", "nan", "0", "0"], 2, ["nan"]),
    ("calibrate-nothing", ["calibrate", "-o", "{d}/p.yaml"], 2, ["TABLE"]),
    # sim
    ("sim-repeats-0", ["sim", "--repeats", "0"], 2, ["--repeats"]),
    ("sim-repeats-negative", ["sim", "--repeats", "-2"], 2, ["--repeats"]),
    ("sim-theta-nan", ["sim", "--theta0-deg", "nan"], 2, ["--theta0-deg"]),
    # fit: durations, geometry, a bag without ring-downs, a table given as a bag
    ("fit-settle-negative", ["fit", "{d}/bag", "--coil-off-skip-s", "-1"], 2, ["--coil-off-skip-s"]),
    ("fit-settle-renamed", ["fit", "{d}/bag", "--settle-s", "0.01"], 2, ["--settle-s is renamed --coil-off-skip-s"]),
    (
        "fit-settle-longer-than-ringdown",
        ["fit", "{d}/bag", "--coil-off-skip-s", "100"],
        2,
        ["--coil-off-skip-s", "every ring-down"],
    ),
    ("fit-negative-spacing", ["fit", "{d}/bag", "--sensor-spacing-m", "-0.01"], 2, ["--sensor-spacing-m"]),
    ("fit-60-m-distance", ["fit", "{d}/bag", "--sensor-distance-m", "60"], 2, ["--sensor-distance-m", "1 m"]),
    ("fit-no-such-topic", ["fit", "{d}/bag", "--raw-topic", "/nope"], 2, ["no ring-down", "/nope"]),
    ("fit-empty-bag", ["fit", "{d}/empty_bag"], 2, ["empty_bag holds no ring-down"]),
    ("map-no-fits", ["map", "{d}/bag"], 2, ["no ring-down fit recorded", "--refit"]),
    ("map-one-orientation", ["map", "{d}/bag", "--refit"], 2, ["{d}/bag", "orientations"]),
    ("map-empty-bag", ["map", "{d}/empty_bag", "--refit"], 2, ["no measurement ring-down"]),
    ("map-a-csv", ["map", "{d}/sweep.csv"], 2, ["not a bag"]),
    ("map-bad-model", ["map", "{d}/bag", "--model", "eq6"], 2, ["--model", "first_principles"]),
    ("fit-a-csv", ["fit", "{d}/sweep.csv"], 2, ["not a bag", "mows lab"]),
    # lab
    (
        "lab-reference-for-a-csv-with-its-own",
        ["lab", "compare", "{d}/sweep.csv", "--reference", "{d}/nothere.yaml"],
        2,
        ["already has reference columns", "give no --reference"],
    ),
    (
        "lab-missing-reference-is-blamed-not-the-table",
        ["lab", "compare", "{d}/sweep_no_reference.csv", "--reference", "{d}/nothere.yaml"],
        2,
        ["error: reference {d}/nothere.yaml does not exist"],
    ),
    (
        "lab-missing-plugin-is-blamed-not-the-table",
        ["lab", "compare", "{d}/sweep.csv", "--plugin", "{d}/nothere.py"],
        2,
        ["error: plugin file {d}/nothere.py does not exist"],
    ),
    (
        "lab-reference-field-in-ut",
        ["lab", "compare", "{d}/sweep_field_in_ut.csv"],
        2,
        ["reference field 16 T", "factor 10 from f00", "µT"],
    ),
    ("lab-f-in-khz", ["lab", "compare", "{d}/sweep_khz.csv"], 2, ["f00", "kHz"]),
    (
        "lab-reference-in-mt-as-t",
        ["lab", "compare", "{d}/sweep_reference_in_mt.csv"],
        2,
        ["the ring-downs move 0.00", "Eq. 6", "a factor 10^3 is a unit, the reference in mT given in T"],
    ),
    ("lab-std-not-physical", ["lab", "compare", "{d}/sweep_huge_std.csv"], 2, ["f_std_hz", "1/10 of f_hz"]),
    ("lab-probe-not-a-number", ["lab", "compare", "{d}/sweep_probe_words.csv"], 2, ["column 'probe'", "not a number"]),
    ("lab-semicolons", ["lab", "compare", "{d}/sweep_semicolons.csv"], 2, ["separated by ';'", "comma"]),
    ("lab-one-row", ["lab", "compare", "{d}/sweep_one_row.csv"], 2, ["1 row", "degrees of freedom"]),
    ("lab-ringdown-negative-f00", ["lab", "ringdown", "{d}/bag", "--f00-hz", "-3"], 2, ["--f00-hz"]),
    # usage: the (sub)command that refuses names itself and its --help
    (
        "fit-unknown-option",
        ["fit", "{d}/bag", "--x"],
        2,
        ["mows fit: error: unrecognized arguments: --x (see mows fit --help)"],
    ),
    (
        "lab-report-unknown-option",
        ["lab", "report", "{d}/sweep.csv", "--x"],
        2,
        ["mows lab report: error: unrecognized arguments: --x (see mows lab report --help)"],
    ),
    (
        "check-hardware-frequency-zero",
        ["check-hardware", "--simulate", "--frequency-hz", "0"],
        2,
        ["--frequency-hz: 0 must be > 0"],
    ),
    ("bench-unknown-suite", ["bench", "nosuch"], 2, ["mows bench: error: ", "'nosuch'", "(see mows bench --help)"]),
    (
        "bench-no-burners",
        ["bench", "latency", "--load", "--burners", "0"],
        2,
        ["mows bench: error: ", "--burners", "at least 1, got '0'"],
    ),
    ("bench-map-runs-word", ["bench", "latency", "--map-runs", "x"], 2, ["--map-runs", "at least 1, got 'x'"]),
    # probe files
    (
        "probe-1000x-moment",
        ["lab", "compare", "{d}/sweep.csv", "--probe", "{d}/probe_1000x.yaml"],
        2,
        ["implausible", "moment_am2"],
    ),
    (
        "probe-two-stops",
        ["lab", "compare", "{d}/sweep.csv", "--probe", "{d}/probe_two_stops.yaml"],
        2,
        ["theta_stop_deg", "theta_stop_rad"],
    ),
]


@pytest.mark.parametrize("argv, status, words", [case[1:] for case in CASES], ids=[case[0] for case in CASES])
def test_a_bad_input_is_one_line_with_its_status_and_changes_nothing(work, capsys, argv, status, words):
    if "{d}/null" in argv and not (work / "null").exists():
        pytest.skip("making a device file needs root")
    before = snapshot(work)
    got = main([word.format(d=work) for word in argv])
    err = capsys.readouterr().err
    assert got == status, err
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for word in words:
        assert word.format(d=work) in err, err
    assert snapshot(work) == before


#: Possible but seldom meant: used as given, with a note or warning that says what it may be.
LAB = ["lab", "compare", "--no-cv"]
WARNING_CASES = [
    ("temperature-in-c", [*LAB, "{d}/sweep_temperature_in_c.csv"], ["temperature_k is unusual", "°C given in K?"]),
    ("duration-in-ms", [*LAB, "{d}/sweep_duration_in_ms.csv"], ["duration_s is unusual", "ms given as s?"]),
    ("amplitude-in-rad", [*LAB, "{d}/sweep_amplitude_in_rad.csv"], ["amplitude_deg lies within", "radians"]),
    ("theta-in-rad", [*LAB, "{d}/sweep_theta_in_rad.csv"], ["theta0_deg lies within", "radians"]),
    ("negative-t", [*LAB, "{d}/sweep_negative_t.csv"], ["t_s is negative"]),
    (
        "reference-20-k",
        [*LAB, "{d}/sweep.csv", "--probe", "{d}/probe_20_k.yaml"],
        ["warning: reference_temperature_k = 20 K is unusual", "°C given in K?"],
    ),
    ("field-10-t", ["sim", "{d}/scene_10_t.yaml"], ["warning: |field_t| = 10 T is unusual", "mT or µT given as T?"]),
]


@pytest.mark.parametrize("argv, words", [c[1:] for c in WARNING_CASES], ids=[c[0] for c in WARNING_CASES])
def test_an_unusual_value_is_used_and_said(work, capsys, argv, words):
    before = snapshot(work)
    assert main([word.format(d=work) for word in argv]) == 0
    out = "".join(capsys.readouterr())
    assert all(word in out for word in words), out
    assert snapshot(work) == before


@pytest.mark.slow  # a fresh interpreter loads the lab: ~10 s each on a loaded machine
@pytest.mark.parametrize(
    "body, how",
    [("os._exit(0)", "os._exit(0)"), ("raise KeyboardInterrupt", "raise KeyboardInterrupt, without a signal")],
    ids=["os-exit", "keyboard-interrupt"],
)
def test_a_plugin_cannot_end_the_command_unseen(tmp_path, body, how):
    """What only the command's own process shows: ``os._exit`` would end it with no word (and
    in a test, the test's process), and a KeyboardInterrupt that no signal raised would pass
    for Ctrl-C (its handlers, in place only there, know)."""
    shutil.copy(SWEEP_TABLE, tmp_path / "sweep.csv")
    (tmp_path / "plugin.py").write_text(PLUGIN.format(body=f"import os\n    {body}"))
    before = snapshot(tmp_path)
    command = [
        sys.executable,
        "-m",
        "mows.cli.main",
        "lab",
        "diagnose",
        "sweep.csv",
        "--plugin",
        "plugin.py",
        "--no-cv",
    ]
    run = subprocess.run([*command, "--no-cv"], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    line = f"mows lab diagnose: error: {tmp_path}/plugin.py:9 tried to end the command ({how}): "
    assert run.returncode == 2 and run.stderr.startswith(line) and len(run.stderr.splitlines()) == 1, run.stderr
    assert snapshot(tmp_path) == before


EMULATOR_CASES = [
    ("scenario-nosuch", ["--scenario", "nosuch"], ["nosuch"]),
    ("cap-negative", ["--cap-a", "-1"], ["--cap-a -1.0"]),
    ("cap-nan", ["--cap-a", "nan"], ["--cap-a nan"]),
    ("watchdog-0-s", ["--watchdog-timeout-s", "0"], ["watchdog"]),
]


@pytest.mark.parametrize("argv, words", [c[1:] for c in EMULATOR_CASES], ids=[c[0] for c in EMULATOR_CASES])
def test_the_emulator_refuses_bad_arguments_in_one_line(work, capsys, argv, words):
    before = snapshot(work)
    assert emulator.main(["--link", str(work / "device"), *argv]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and all(word in err for word in words), err
    assert snapshot(work) == before


def test_the_emulator_names_a_missing_directory_not_an_existing_file(work, capsys):
    assert emulator.main(["--link", str(work / "nodir" / "dev")]) == 2
    err = capsys.readouterr().err
    assert "exists" not in err and "No such file or directory" in err, err


# --- a directory that cannot be written -------------------------------------------------------
def lock(directory: pathlib.Path) -> None:
    """Make ``directory`` unwritable for this user: its mode bits, or for root (whom they do not
    stop) the immutable attribute; skip where the filesystem has none."""
    if os.geteuid() != 0:
        directory.chmod(0o555)
    elif shutil.which("chattr") is None or subprocess.run(["chattr", "+i", str(directory)]).returncode != 0:
        pytest.skip("root cannot be kept from a directory here: no immutable attribute")


def unlock(directory: pathlib.Path) -> None:
    if os.geteuid() == 0:
        subprocess.run(["chattr", "-i", str(directory)], check=True)
    directory.chmod(0o755)


@pytest.mark.parametrize(
    "argv",
    [
        ["sim", "--out", "{o}/x.npz"],
        ["lab", "report", str(SWEEP_TABLE), "-o", "{o}/r.html"],
        ["calibrate", str(CALIBRATION_TABLE), "-o", "{o}/p.yaml"],
    ],
    ids=["sim", "lab-report", "calibrate"],
)
def test_an_unwritable_output_directory_is_named_not_an_input(tmp_path, capsys, argv):
    locked = tmp_path / "locked"
    locked.mkdir()
    lock(locked)
    try:
        status = main([word.format(o=locked) for word in argv])
    finally:
        unlock(locked)
    err = capsys.readouterr().err
    assert status == 2 and len(err.splitlines()) == 1, err
    assert f"error: output {locked}/" in err and f"directory {locked} is not writable" in err, err
    assert list(locked.iterdir()) == []


def test_a_directory_locked_while_its_output_is_written_is_named(tmp_path):
    """The outputs' directory locked between the first check and the rename: the refusal names
    it, and the old file is left as it was."""
    target = tmp_path / "x.txt"
    target.write_text("old")
    with pytest.raises(OutputRefused, match=f"directory {tmp_path} is not writable"):
        with writing([target], force=True) as outputs:
            outputs.temporaries[0].write_text("new")
            lock(tmp_path)
    unlock(tmp_path)
    assert target.read_text() == "old"


def test_a_second_output_that_cannot_be_replaced_leaves_the_first_as_it_was(tmp_path):
    """Two outputs, the second an immutable file that its rename cannot replace (after every check
    has passed): the first, already renamed into place, is put back, old content or none."""
    if os.geteuid() != 0 or shutil.which("chattr") is None:
        pytest.skip("only root sets the immutable attribute that makes a rename fail after the checks")
    first, new, second = tmp_path / "a" / "p.yaml", tmp_path / "a" / "new.txt", tmp_path / "b" / "t.csv"
    for path, text in ((first, "old probe"), (second, "old table")):
        path.parent.mkdir(exist_ok=True)
        path.write_text(text)
    if subprocess.run(["chattr", "+i", str(second)]).returncode != 0:
        pytest.skip("this filesystem has no immutable attribute")
    before = snapshot(tmp_path)
    try:
        with pytest.raises(OutputRefused, match=f"output {second}"):
            with writing([first, new, second], force=True) as outputs:
                for temporary in outputs.temporaries:
                    temporary.write_text("new")
    finally:
        subprocess.run(["chattr", "-i", str(second)], check=True)
    assert snapshot(tmp_path) == before


# --- interrupts ------------------------------------------------------------------------------
def interrupt(*_args, **_kwargs):
    raise KeyboardInterrupt


def test_ctrl_c_while_writing_two_outputs_leaves_neither(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(calibrate_cli, "write_points", interrupt)  # the second output, after the first
    status = main(
        [
            "calibrate",
            str(CALIBRATION_TABLE),
            "--gradient-scenario",
            "calibration_gradient",
            "-o",
            str(tmp_path / "p.yaml"),
            "--table",
            str(tmp_path / "t.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert status == 130 and err == "mows calibrate: interrupted\n", err
    assert list(tmp_path.iterdir()) == []


def interrupted_import(*_args, **_kwargs):
    """What Ctrl-C in an extension module's initialisation raises (scipy's, on a slow start)."""
    try:
        raise KeyboardInterrupt
    except KeyboardInterrupt as error:
        raise ImportError("initialization failed") from error


@pytest.mark.parametrize("where", ["loading the subcommand", "running it"])
def test_ctrl_c_while_a_module_loads_is_one_line_and_130(tmp_path, capsys, monkeypatch, where):
    if where == "loading the subcommand":
        monkeypatch.setattr("mows.cli.main.importlib.import_module", interrupted_import)
    else:
        monkeypatch.setattr(sim_cli, "simulate_cycle", interrupted_import)
    prog = "mows sim"
    assert main(["sim", "--out", str(tmp_path / "x.npz")]) == 130
    assert capsys.readouterr().err == f"{prog}: interrupted\n"
    assert list(tmp_path.iterdir()) == []


def test_the_entry_point_imports_nothing_slow_before_ctrl_c_is_caught():
    """The console script imports mows.cli.main outside any handler: numpy there (~0.5 s on a
    loaded machine) would make Ctrl-C at the start a traceback."""
    probe = "import sys, mows.cli.main; print(sorted({'numpy', 'scipy', 'yaml'} & set(sys.modules)))"
    run = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=60, check=True)
    assert run.stdout.strip() == "[]", run.stdout


def test_ctrl_c_in_a_simulation_is_one_line_and_130(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(sim_cli, "simulate_cycle", interrupt)
    assert main(["sim", "--out", str(tmp_path / "x.npz")]) == 130
    assert capsys.readouterr().err == "mows sim: interrupted\n"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow  # a fresh interpreter loads the simulator and the fit: ~20 s on a loaded machine
def test_sigint_to_a_running_command_ends_it_with_130_and_no_output(tmp_path):
    """The real signal: the command is interrupted once it has printed its first fit.

    Its SIGINT is the default, as from a terminal: a suite started as a shell's background job
    inherits SIGINT ignored, which Python keeps (GNU env's --default-signal)."""
    out = tmp_path / "x.npz"
    command = [sys.executable, "-m", "mows.cli.main", "sim", "--fit", "--repeats", "200", "--out", str(out)]
    process = subprocess.Popen(
        ["env", "--default-signal=INT", *command],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stdout.readline().startswith("θ0")
    process.send_signal(signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130 and err == "mows sim: interrupted\n", err
    assert list(tmp_path.iterdir()) == []


# --- what works ---------------------------------------------------------------------------------
def test_force_replaces_a_regular_file_and_says_so(tmp_path, capsys):
    out = tmp_path / "x.npz"
    out.write_text("old")
    assert main(["sim", "--theta0-deg", "0", "90", "--out", str(out), "--force"]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == f"replaced {out}: 2 cycles"
    with np.load(out) as cycles:  # the documented form with two orientations: cycles of two lengths
        assert cycles["samples_t"].shape[0] == 2 and len(set(cycles["n_samples"])) == 2
        for samples, n in zip(cycles["samples_t"], cycles["n_samples"]):
            assert np.isfinite(samples[:n]).all() and np.isnan(samples[n:]).all()


@pytest.mark.slow  # the lab's whole report: ~7 s of CPU
def test_lab_report_json_keeps_stdout_for_the_json(tmp_path, capsys):
    page = tmp_path / "report.html"
    assert main(["lab", "report", str(SWEEP_TABLE), "-o", str(page), "--json", "--no-cv"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["base"]["n"] > 0
    assert captured.err.splitlines()[-1] == f"wrote {page}"


# --- kills ----------------------------------------------------------------------------------------
CALIBRATE = ["calibrate", str(CALIBRATION_TABLE), "--gradient-scenario", "calibration_gradient", "--force"]

KILLED_AFTER_FIRST_RENAME = """
import os, signal, sys
import mows.records.files as files
from mows.cli.inputs import report_errors
from mows.cli.main import main
renamed = []
def replace(source, target):
    if os.path.basename(target) not in ("p.yaml", "t.csv"):  # numba's cache, in a fresh checkout
        return os.rename(source, target)
    if renamed:  # SIGKILL between the first rename and the second: no clean-up runs
        os.kill(os.getpid(), signal.SIGKILL)
    renamed.append(target)
    os.rename(source, target)
files.os.replace = replace
sys.exit(main(sys.argv[1:]))
"""


def digests(directory: pathlib.Path) -> dict[str, str]:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(directory.iterdir())}


def killed_calibration(tmp_path: pathlib.Path) -> tuple[list[str], dict[str, str]]:
    """A calibration's two outputs over an older pair, killed between its two renames: the
    command, and the digests of the older pair."""
    outputs = ["-o", str(tmp_path / "p.yaml"), "--table", str(tmp_path / "t.csv")]
    (tmp_path / "p.yaml").write_text("old probe\n")
    (tmp_path / "t.csv").write_text("old table\n")
    before = digests(tmp_path)
    run = subprocess.run([sys.executable, "-c", KILLED_AFTER_FIRST_RENAME, *CALIBRATE, *outputs], timeout=600)
    assert run.returncode == -signal.SIGKILL
    leftovers = [p.name for p in tmp_path.iterdir() if p.name.startswith(".")]
    assert any(name.endswith(".commit") for name in leftovers), leftovers  # the journal of the cut commit
    assert digests(tmp_path)["p.yaml"] != before["p.yaml"] and digests(tmp_path)["t.csv"] == before["t.csv"]
    return [*CALIBRATE, *outputs], before


@pytest.mark.slow  # two calibrations in fresh interpreters: ~20 s
def test_a_kill_between_two_renames_is_undone_and_a_second_run_does_the_job(tmp_path, capsys):
    command, before = killed_calibration(tmp_path)
    assert main(command) == 0
    after = digests(tmp_path)
    assert sorted(after) == ["p.yaml", "t.csv"]  # no temporary, copy or journal left
    assert after["p.yaml"] != before["p.yaml"] and after["t.csv"] != before["t.csv"]
    assert "replaced" in capsys.readouterr().out


def test_the_old_pair_is_put_back_from_the_journal_of_a_killed_commit(tmp_path):
    _, before = killed_calibration(tmp_path)
    assert recover(tmp_path) == [tmp_path / "p.yaml"]
    assert digests(tmp_path) == before


@pytest.mark.slow  # a fresh interpreter loads the simulator: ~10 s
def test_sigterm_to_a_running_command_ends_it_with_143_and_no_output(tmp_path):
    out = tmp_path / "x.npz"
    command = [sys.executable, "-m", "mows.cli.main", "sim", "--fit", "--repeats", "200", "--out", str(out)]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout.readline().startswith("θ0")
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 143 and err == "mows sim: terminated\n", err
    assert list(tmp_path.iterdir()) == []


KILLED_WHILE_WRITING = """
import os, signal, sys
from mows.records.files import writing
with writing([sys.argv[1]]) as outputs:
    outputs.temporaries[0].write_text("torn")
    os.kill(os.getpid(), signal.SIGKILL)
"""


def test_a_killed_writer_s_temporary_is_removed_by_the_next_write_and_nothing_else(tmp_path):
    out = tmp_path / "x.csv"
    killed = subprocess.run([sys.executable, "-c", KILLED_WHILE_WRITING, str(out)], timeout=120)
    assert killed.returncode == -signal.SIGKILL
    left = sorted(p.name for p in tmp_path.iterdir())
    assert len(left) == 2 and left[0].endswith(".partial.csv") and left[1].endswith(".writing"), left
    # names of the same form that no writer's note vouches for: a user's files, never removed
    lookalikes = [".x.csv.999999.abcdefgh.partial.csv", ".x.csv.999999.abcdefgh.replaced"]
    running = f".x.csv.{os.getpid()}.def456gh.partial.csv"  # a writer still at work: left alone
    for name in [*lookalikes, running]:
        (tmp_path / name).write_text("the user's")
    with writing([out]) as outputs:
        outputs.temporaries[0].write_text("whole")
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([*lookalikes, running, "x.csv"])


@pytest.mark.slow  # a fresh interpreter loads the simulator: ~10 s
def test_a_reader_that_leaves_stdout_ends_the_command_quietly(tmp_path):
    """``mows sim --fit … | head -1``: status 141 (as a shell reports SIGPIPE), nothing on stderr."""
    command = [sys.executable, "-m", "mows.cli.main", "sim", "--fit", "--repeats", "200", "--out", str(tmp_path / "x")]
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert process.stdout.readline().startswith("θ0")
    process.stdout.close()
    err = process.stderr.read()
    assert process.wait(timeout=120) == 141 and err == "", err
    assert list(tmp_path.iterdir()) == []


def test_warnings_on_the_way_to_an_error_are_not_said_and_on_success_once_each(capsys):
    def failing() -> int:
        np.log(np.zeros(3))  # numpy: "divide by zero encountered in log", as over a bad column
        raise ValueError("the column is bad")

    def succeeding() -> int:
        for _ in range(3):
            np.log(np.zeros(3))
        return 0

    assert report_errors("mows x", failing) == 2
    assert capsys.readouterr().err == "mows x: error: the column is bad\n"
    assert report_errors("mows x", succeeding) == 0
    assert capsys.readouterr().err == "mows x: warning: divide by zero encountered in log\n"
