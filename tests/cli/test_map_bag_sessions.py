"""`mows map BAG` cuts a recording into the sweeps the mapper made, as the mapper cut them.

Requirement: the recording holds cycles another client ran before a sweep, in another field (a
coil left on), the sweep the mapper published (naming its cycles) and three trailing cycles of a
sweep the recording stopped in. `mows map` makes the published sweep again from its own cycles
alone (the field within 4σ of the truth, χ²/dof that of noise), says the trailing one is too short
beside it instead of exiting 2, and names the cycles it left out. The fits are the exact
frequencies of the full potential (not the decomposition's model) plus their σ of noise."""

import json

import numpy as np

from mows.cli.main import main
from mows.device.recording import bags
from mows.physics.field import UniformField
from mows.physics.pose import Pose
from mows.physics.potential import ArcPotential
from mows.physics.probe import PAPER_PROBE as P
from recorded_bags import EXCITATION, STORE, header, ringdown_fit_message, ringdown_message

FIELD_T = np.array([30e-6, -20e-6, 0.0])
BEFORE_FIELD_T = np.array([-60e-6, 45e-6, 0.0])  # another client's cycles, another field
STD_HZ = 1e-3  # ringdown_fit_message's σ
BEFORE, SWEEP, AFTER = (1, 2), tuple(range(3, 15)), (15, 16, 17)  # cycle ids


def _frequency_hz(field_t, theta0_rad) -> float:
    return float(ArcPotential.from_source(P, UniformField(field_t), Pose(theta0_rad=theta0_rad)).frequency_hz())


def _cycle(cycle_id: int, theta0_rad: float, field_t, rng) -> list[bags.BagMessage]:
    """A cycle of one ring-down at second ``cycle_id``: its announcement and the estimator's fit."""
    f_hz = _frequency_hz(field_t, theta0_rad) + STD_HZ * rng.standard_normal()
    fit = ringdown_fit_message(cycle_id + 0.6, theta0_rad, f_hz)
    fit.status_name, fit.frequency_shift_hz, fit.frequency_shift_std_hz = "OK", f_hz - P.f00_hz, STD_HZ
    announced = ringdown_message(cycle_id * 1000, 1000.0, cycle_id, theta0_rad, f_hz)
    return [
        bags.BagMessage("/mows/excitation", EXCITATION, cycle_id * 1_000_000_000, announced),
        bags.BagMessage("/mows/ringdown", "mows_msgs/msg/RingdownFit", (cycle_id * 10 + 6) * 100_000_000, fit),
    ]


def _published_sweep(seconds: float) -> bags.BagMessage:
    """The mapper's SweepDecomposition naming its cycles (its numbers, zero here, are not read back)."""
    kind = "mows_msgs/msg/SweepDecomposition"
    fields = {name: bags.zero(k, detail, STORE) for name, (k, detail) in STORE.fielddefs[kind][1]}
    fields.update(header=header(seconds, "mows_rotation_plane"), sweep_id=1, model="first_principles")
    fields.update(cycle_ids=np.array(SWEEP, dtype=np.uint64), f00_hz=P.f00_hz, n_points=len(SWEEP))
    return bags.BagMessage("/mows/sweep", kind, round(seconds * 1e9), STORE.types[kind](**fields))


def _recording(path, seed=0):
    rng = np.random.default_rng(seed)
    angles = np.radians(np.arange(0.0, 360.0, 30.0))
    messages = [m for k, c in enumerate(BEFORE) for m in _cycle(c, angles[k + 3], BEFORE_FIELD_T, rng)]
    messages += [m for c, theta in zip(SWEEP, angles) for m in _cycle(c, theta, FIELD_T, rng)]
    messages.append(_published_sweep(SWEEP[-1] + 0.9))
    messages += [m for c, theta in zip(AFTER, angles) for m in _cycle(c, theta, FIELD_T, rng)]
    return bags.write_bag(path / "session", sorted(messages, key=lambda m: m.timestamp_ns))


def test_the_published_sweep_is_made_again_from_its_own_cycles_and_a_short_one_beside_it(tmp_path, capsys):
    bag = _recording(tmp_path)
    assert main(["map", str(bag), "--json"]) == 0
    made = json.loads(capsys.readouterr().out)
    sweep, after = made["sweeps"]
    assert sweep["cycle_ids"] == list(SWEEP) and after["cycle_ids"] == list(AFTER)
    assert made["left_out_cycle_ids"] == list(BEFORE)
    assert sweep["ok"] and not after["ok"] and "orientation" in after["message"], after
    (field_map,) = sweep["maps"]
    error = np.subtract(field_map["field_t"], FIELD_T[:2])
    assert np.all(np.abs(error) < 4 * np.array(field_map["field_std_t"])), (error, field_map["field_std_t"])
    # χ²/dof of 12 points with 1 mHz noise: below 2.5 but for a chance of about 1 in 200
    assert field_map["chi2_dof"] < 2.5 and field_map["points"] == len(SWEEP)


def test_each_sweep_has_its_line_and_the_left_out_cycles_are_named(tmp_path, capsys):
    bag = _recording(tmp_path)
    assert main(["map", str(bag)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith(f"sweep 1 ({len(SWEEP)} orientations): ") and "not made again" not in lines[0]
    assert lines[1].startswith(f"after the last recorded sweep ({len(AFTER)} orientations): not made again")
    assert lines[2] == "2 cycles in no recorded sweep left out (cycle ids 1, 2)"
