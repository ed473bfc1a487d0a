"""A bag of ring-down fits of two probes (``probe_id``, docs/multi_probe.md) read by the lab.

Requirement: ``from_bag`` gives the ``probe`` column and each probe's start swings from its
own fits; ``mows lab compare BAG`` then fits one f00 per probe. The two probes ring 4 Hz
apart with σ = 1 mHz: kept apart, χ²/dof is that of the noise (the 95 % bound of χ²/dof for
38 degrees of freedom is 1.4); mixed, one f00 for both puts χ²/dof near (2 Hz / 1 mHz)² = 4e6.
A bag of one probe keeps its table without the column. ``mows fit`` without ``--probes``, which
would re-fit the raw samples one probe per window, refuses a bag of several probes in one line.
"""

import re

import numpy as np

from mows.cli.main import main
from mows.device.recording import bags
from mows.lab import from_bag
from mows.lab.data.table import PROBE
from recorded_bags import EXCITATION, ringdown_fit_message, ringdown_message

F00_HZ = {0: 112.5, 1: 116.5}
STD_HZ = 1e-3


def write(path, probes, seed=1):
    """20 windows, each with one fit per probe in ``probes`` (probe 1 starting from 0.3 rad, probe 0 from 0.4)."""
    rng = np.random.default_rng(seed)
    messages = [
        bags.BagMessage(
            "/mows/ringdown",
            "mows_msgs/msg/RingdownFit",
            10**9 * s + k,
            ringdown_fit_message(
                s,
                0.1 * (s % 8),
                F00_HZ[k] + STD_HZ * rng.standard_normal(),
                probe_id=k,
                amplitude_rad=0.4 - 0.1 * k,
                determined=("amplitude_rad", "rest_offset_rad"),
            ),
        )
        for s in range(1, 21)
        for k in probes
    ]
    return bags.write_bag(path, messages)


def test_a_bag_of_two_probes_gives_a_probe_column_and_each_probes_start_swings(tmp_path):
    table = from_bag(write(tmp_path / "bag", (0, 1)))
    probe = table.columns[PROBE]
    assert sorted(np.unique(probe).tolist()) == [0.0, 1.0] and np.sum(probe == 1) == 20
    np.testing.assert_allclose(table.columns["amplitude_deg"][probe == 0], np.degrees(0.4))
    np.testing.assert_allclose(table.columns["amplitude_deg"][probe == 1], np.degrees(0.3))
    assert not from_bag(write(tmp_path / "one", (0,))).has(PROBE)


def chi2_dof(capsys, argv):
    assert main(argv) == 0
    out = capsys.readouterr().out
    return float(re.search(r"χ²/dof\s*=?\s*([0-9.e+]+)", out).group(1)), out


def test_the_lab_keeps_the_probes_of_a_bag_apart(tmp_path, capsys):
    chi2, out = chi2_dof(capsys, ["lab", "compare", str(write(tmp_path / "bag", (0, 1)))])
    assert chi2 < 1.4, out


def test_mows_fit_refuses_a_bag_of_several_probes_in_one_line(tmp_path, capsys):
    """Without --probes mows fit would re-fit the raw samples one probe per window. Whether the
    bag says it holds several by its fits or by its excitations, the refusal names the probes
    and says to pass --probes, and writes no table."""
    excitation = ringdown_message(0, 10_000.0, 1, 0.0, 112.5)
    excitation.probe_ids = np.array([0, 2], np.uint8)
    excitation.probe_frequency_hz, excitation.probe_theta0_rad = np.array([112.5, 125.0]), np.zeros(2)
    announced = bags.write_bag(tmp_path / "announced", [bags.BagMessage("/mows/excitation", EXCITATION, 1, excitation)])
    for path, probes in ((write(tmp_path / "fitted", (0, 1)), "0, 1"), (announced, "0, 2")):
        table = tmp_path / f"{path.name}.csv"
        assert main(["fit", str(path), "--csv", str(table)]) == 2
        error = capsys.readouterr().err.strip()
        assert len(error.splitlines()) == 1 and f"probes {probes}" in error and "--probes" in error, error
        assert not table.exists()
