"""Probe constants and calibration inverses against the paper's reported numbers."""

import math
import re

import pytest

from mows.physics.probe import PAPER_PROBE, Probe, inertia_from_beta0, lever_from_inertia, spring_from_beta0


def test_paper_calibration_reproduces_reported_constants():
    # Main text after Eq. 10: kM = 1.36e-5 N·m, J = 2.72e-11 kg·m²; l = 1.9 mm from a = 7.2 mg.
    assert PAPER_PROBE.spring_nm_per_rad == pytest.approx(1.36e-5, rel=5e-3)
    assert PAPER_PROBE.inertia_kgm2 == pytest.approx(2.72e-11, rel=5e-3)
    assert PAPER_PROBE.lever_m == pytest.approx(1.9e-3, rel=0.03)
    assert PAPER_PROBE.f00_hz == pytest.approx(112.48, abs=1e-9)
    assert PAPER_PROBE.beta0_hz_per_t == pytest.approx(3.68e3, rel=1e-12)


def test_calibration_inverses_agree_with_eq10_up_to_damping():
    spring = spring_from_beta0(112.48, 0.89e-3, 3.68e3)
    inertia = inertia_from_beta0(0.89e-3, 3.68e3, 112.48)
    # Eq. 10 neglects damping: J·(2π f00)² = kM exactly.
    assert inertia * (2 * math.pi * 112.48) ** 2 == pytest.approx(spring, rel=1e-12)
    # The damped calibration differs by δ²/(2π f00)² only.
    assert PAPER_PROBE.inertia_kgm2 / inertia - 1 == pytest.approx(-((1.8 / (2 * math.pi * 112.48)) ** 2), rel=1e-3)
    assert lever_from_inertia(inertia, 7.2e-6) ** 2 * 7.2e-6 == pytest.approx(inertia, rel=1e-12)


def test_spring_cancellation_field_is_minus_15_mT():
    # docs/physics.md §5: f → 0 at B = −kM/m ≈ −15.3 mT.
    assert PAPER_PROBE.cancellation_field_t == pytest.approx(-15.3e-3, rel=5e-3)


def test_thermal_coefficient_gives_minus_15_mhz_per_kelvin():
    hot = PAPER_PROBE.replace(spring_nm_per_rad=PAPER_PROBE.spring_at(PAPER_PROBE.reference_temperature_k + 1.0))
    assert (hot.f00_hz - PAPER_PROBE.f00_hz) * 1e3 == pytest.approx(-14.6, abs=0.2)


def test_yaml_round_trip_and_f00_stand_in(tmp_path):
    path = tmp_path / "probe.yaml"
    PAPER_PROBE.to_yaml(path)
    assert Probe.from_yaml(path) == PAPER_PROBE
    data = PAPER_PROBE.to_dict()
    del data["inertia_kgm2"]
    assert Probe.from_dict(data).inertia_kgm2 == pytest.approx(PAPER_PROBE.inertia_kgm2, rel=1e-12)


def test_contradictory_or_unphysical_probe_files_are_refused():
    data = PAPER_PROBE.to_dict()
    data["f00_hz"] = 120.0
    with pytest.raises(ValueError, match="contradicts"):
        Probe.from_dict(data)
    with pytest.raises(ValueError, match="unknown probe keys"):
        Probe.from_dict({**PAPER_PROBE.to_dict(), "moment": 1.0})
    with pytest.raises(ValueError, match="spring_nm_per_rad"):
        PAPER_PROBE.replace(spring_nm_per_rad=-1.0)
    with pytest.raises(ValueError, match="overdamped"):
        PAPER_PROBE.replace(damping_per_s=1e4)


def test_the_moment_follows_its_temperature_coefficient_from_the_probe_file(tmp_path):
    """m(T) = m·(1 + α·(T − T_ref)); the default α = 0 leaves the probe as it is."""
    assert PAPER_PROBE.moment_temp_coeff_per_k == 0.0
    assert PAPER_PROBE.at_temperature(350.0) is PAPER_PROBE
    path = tmp_path / "probe.yaml"
    assert "moment_temp_coeff_per_k" not in PAPER_PROBE.yaml_text()
    path.write_text(PAPER_PROBE.yaml_text() + "moment_temp_coeff_per_k: -1.2e-3\n")
    probe = Probe.from_yaml(path)
    probe.to_yaml(tmp_path / "again.yaml")
    assert Probe.from_yaml(tmp_path / "again.yaml") == probe
    warm = probe.at_temperature(probe.reference_temperature_k + 10.0)
    assert warm.moment_am2 == pytest.approx(0.988 * PAPER_PROBE.moment_am2, rel=1e-12)
    assert (warm.spring_nm_per_rad, warm.magnet_mass_kg) == (probe.spring_nm_per_rad, probe.magnet_mass_kg)
    with pytest.raises(ValueError, match=r"moment_temp_coeff_per_k = 0\.05 is out of range"):
        PAPER_PROBE.replace(moment_temp_coeff_per_k=0.05)


BAD_PROBE_FILES = {  # the paper's probe file with a line replaced (or added), and the refusal after the file's name
    "a NaN": ("f00_hz: .nan", r"f00_hz = nan must be a finite number"),
    "text for a number": ('lever_m: "1.9e-3"', r"lever_m = '1.9e-3' is not a number"),
    "out of range": ("theta_stop_rad: 2.0", r"theta_stop_rad = 2.0 is out of range: must be finite and in \(0, pi/2\)"),
    "a key twice": (
        "moment_am2: 1.0e-3\nmoment_am2: 1.0e-3",
        r"not valid YAML: line \d+, column 1: key 'moment_am2' is given twice",
    ),
    "not YAML": ("lever_m: [1", r"not valid YAML: line \d+, column \d+: expected ',' or '\]', but got ':'"),
    "a list": (None, "a probe file is a mapping of constants, got list"),
}


def with_line(text, line):
    """``text`` with the line of ``line``'s key replaced by it."""
    key = line.split(":")[0]
    return "\n".join(line if old.startswith(key + ":") else old for old in text.splitlines()) + "\n"


@pytest.mark.parametrize("case", BAD_PROBE_FILES)
def test_a_bad_probe_file_is_one_line_naming_the_file_key_and_value(tmp_path, case):
    line, message = BAD_PROBE_FILES[case]
    path = tmp_path / "probe.yaml"
    path.write_text("- 1\n" if line is None else with_line(PAPER_PROBE.yaml_text(), line))
    with pytest.raises(ValueError) as refused:
        Probe.from_yaml(path)
    assert re.fullmatch(f"probe file {re.escape(str(path))}: {message}", str(refused.value)), refused.value


def test_probe_file_numbers_are_read_as_yaml_1_2(tmp_path):
    """``7.2e-6`` and ``7.2E-6`` with no dot, ``.89e-3`` without a leading digit: numbers."""
    path = tmp_path / "probe.yaml"
    path.write_text(
        "moment_am2: .89e-3\nmagnet_mass_kg: 72E-7\nf00_hz: +112.48\nbeta0_rel_std: 1e-2\nspring_nm_per_rad: 1360e-8\n"
    )
    probe = Probe.from_yaml(path)
    assert (probe.moment_am2, probe.magnet_mass_kg, probe.beta0_rel_std) == (0.89e-3, 7.2e-6, 0.01)
    assert probe.f00_hz == pytest.approx(112.48, rel=1e-12) and probe.spring_nm_per_rad == 1.36e-5
