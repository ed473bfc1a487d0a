"""`mows lab ringdown BAG`: inside one recorded ring-down, the chirp and the effect that explains it.

Independent physics: the simulator integrates the full potential in the time domain; the
diagnosis predicts the chirp by first-harmonic balance of the Eq. 6 field along the axis, which
it takes from the ring-down's own frequency. In 1.5 mT along the axis the field spring weakens
with amplitude (2J1(A)/A − 1 ≈ −A²/8): the frequency rises by ≈ 80 mHz as the swing decays
from 24° to 13° at θ0 = 0°, and falls by as much at 180° where the field opposes the moment.
In the Earth's field alone the predicted chirp is < 1 mHz, far below a piece's σ.
"""

import json
import math

import pytest

from mows.cli.main import main
from mows.physics.field import UniformField
from mows.sim.scenario import load_scenario
from mows.sim.sections import Environment
from recorded_bags import record_cycles

STRONG_T = 1.5e-3


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    directory = tmp_path_factory.mktemp("ringdown_bags")
    earth = load_scenario()
    strong = earth.replace(environment=Environment(sources=(UniformField((STRONG_T, 12e-6, -43.6e-6)),)))
    return {
        "strong": record_cycles(directory / "strong", strong, (0.0, 180.0), 3)[0],
        "earth": record_cycles(directory / "earth", earth, (0.0, 90.0), 3)[0],
    }


def diagnose(path, capsys):
    assert main(["lab", "ringdown", str(path), "--json"]) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


def test_a_strong_field_chirps_by_the_finite_amplitude_it_predicts(bags, capsys):
    found = diagnose(bags["strong"], capsys)
    assert [round(math.degrees(d["theta0_rad"])) for d in found] == [0, 180]
    for item, sign in zip(found, (1, -1)):
        assert item["verdict"] == "finite_amplitude", item["explanation"]
        assert item["constant_p_value"] < 1e-6  # a constant frequency fails inside the ring-down
        assert abs(item["chirp_ratio"] - 1.0) <= 3 * item["chirp_ratio_std"]
        assert item["field_along_axis_t"] == pytest.approx(sign * STRONG_T, rel=0.02)
        # The frequency falls with amplitude where the field stiffens the spring, rises where it softens it.
        assert sign * item["slope_hz_per_rad2"] < 0 and sign * item["predicted_slope_hz_per_rad2"] < 0


def test_the_earths_field_alone_shows_no_chirp(bags, capsys):
    for item in diagnose(bags["earth"], capsys):
        assert item["verdict"] == "constant", item["explanation"]
        assert item["constant_p_value"] > 1e-3


def test_the_text_names_the_effect_and_shows_the_pieces(bags, capsys):
    assert main(["lab", "ringdown", str(bags["strong"]), "--cycle", "1"]) == 0
    out = capsys.readouterr().out
    assert "cycle 1" in out and "cycle 2" not in out
    assert "verdict: finite_amplitude" in out and "predicted (mHz)" in out


def assert_refused(command, words, capsys):
    assert main(command) == 2
    err = capsys.readouterr().err
    assert words in err and len(err.strip().splitlines()) == 1, err


def test_a_missing_bag_is_one_line_and_status_2(tmp_path, capsys):
    assert_refused(["lab", "ringdown", str(tmp_path / "nothing")], "does not exist", capsys)


def test_a_cycle_the_bag_does_not_hold_is_one_line_and_status_2(bags, capsys):
    assert_refused(["lab", "ringdown", str(bags["strong"]), "--cycle", "7"], "cannot diagnose cycle 7", capsys)
