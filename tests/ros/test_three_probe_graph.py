"""Three probes mapped at once through the real node graph, as ``make demo DEMO_ARGS="--scenario
three_probes"`` runs it: the driver excites the three probes of the three_probes scene together
(100, 112.5 and 125 Hz, 5 cm apart about the anti-Helmholtz pair's centre), the estimator fits
each window jointly, and the mapper decomposes each probe with its neighbours' fields in the model.

Requirements: every ring-down of the sweep fits (the tones swing each probe as planned, so the
joint model describes every window, the first cycle's too); every probe is mapped without its
neighbours' fields in its own (within 0.4 µT and 0.15 mT/m: the neighbours' field at 5 cm is
1.4 µT); every probe's field and gradient (15 components) lie within their σ of the truth at its
magnet (the field there plus (l²/4)·∂²B/∂z², what a sweep determines: docs/multi_probe.md).
"Every one of 15 within 2σ" fails by chance in half of all draws even with a calibrated σ, so
the test holds what a calibrated σ gives with a margin, at least 12 of 15 within 2σ (fewer
happens with probability 0.4 %, binomial with p = 0.046), and none beyond 5σ. Three runs gave
15 of 15 within 2σ (largest 1.7–2.0σ); with each ring-down's swing taken about the undeflected
lever instead, one run in three had probe 0's Gxx at 3.7σ, and a small common offset of probe 0 remains
(docs/multi_probe.md)."""

import csv
import re
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
        return run.stdout, list(csv.DictReader(file)), log


def test_every_ring_down_fits(demo):
    _, _, log = demo
    failed = [line for line in log.splitlines() if "ring-down fit:" in line]
    assert not failed, "\n".join(failed)


def test_every_probe_is_decomposed(demo):
    stdout, rows, _ = demo
    assert sorted({int(row["probe_id"]) for row in rows}) == [0, 1, 2]
    assert len(rows) == 15
    # How long the map took after the last fit is said (a figure, not a requirement here:
    # mows bench latency reports it).
    assert re.search(r"the field map came \d+\.\d s after the last ring-down's fit", stdout), stdout[-2000:]


def test_each_probe_is_mapped_without_its_neighbours_fields(demo):
    # The neighbours' field at 5 cm is 1.4 µT, their gradient 0.04 mT/m: taken for the probe's
    # own, or with ring-downs taken to start from the housing stop, the map is off by more.
    stdout, rows, _ = demo
    error = np.array([float(row["value"]) - float(row["truth"]) for row in rows])
    field = np.array([row["quantity"].startswith("b") for row in rows])
    assert np.all(np.abs(error[field]) < 0.4e-6), stdout[-2000:]
    assert np.all(np.abs(error[~field]) < 0.15e-3), stdout[-2000:]


def test_each_probes_field_and_gradient_lie_within_their_sigma(demo):
    stdout, rows, _ = demo
    pulls = np.array([float(row["pull"]) for row in rows])
    assert np.all(np.isfinite(pulls)), stdout[-2000:]
    assert np.sum(np.abs(pulls) <= 2.0) >= 12, stdout[-2000:]
    assert np.max(np.abs(pulls)) < 5.0, stdout[-2000:]
