"""Three probes mapped at once through the real node graph, as ``make demo DEMO_ARGS="--scenario
three_probes"`` runs it: the driver excites the three probes of the three_probes scene together
(100, 112.5 and 125 Hz, 5 cm apart about the anti-Helmholtz pair's centre), the estimator fits
each window jointly, and the mapper decomposes each probe with its neighbours' fields in the model.

Requirements: every ring-down of the sweep fits (the tones swing each probe as planned, so the
joint model describes every window, the first cycle's too); every probe is mapped without its
neighbours' fields in its own (within 0.4 µT and 0.15 mT/m: the neighbours' field at 5 cm is
1.4 µT); every probe's field and gradient (15 components) lie within their σ of the truth at its
magnet (the field there plus (l²/4)·∂²B/∂z², what a sweep determines: docs/multi_probe.md);
the session, recorded, replays offline (`mows map`) to the map the graph published: from the
recorded fits exactly, and from its raw stream fitted again within a fraction of σ.
"Every one of 15 within 2σ" fails by chance in half of all draws even with a calibrated σ, so
the test holds what a calibrated σ gives with a margin, at least 12 of 15 within 2σ (fewer
happens with probability 0.4 %, binomial with p = 0.046), and none beyond 5σ. Three runs gave
15 of 15 within 2σ (largest 1.7–2.0σ); with each ring-down's swing taken about the undeflected
lever instead, one run in three had probe 0's Gxx at 3.7σ, and a small common offset of probe 0 remains
(docs/multi_probe.md)."""

import csv
import json
import re
import subprocess
import sys
from typing import NamedTuple

import numpy as np
import pytest
import yaml

from mows.cli.main import main
from mows.device.recording.bags import read_bag

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]


class Demo(NamedTuple):
    stdout: str
    rows: list
    log: str
    out: object


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
            "--record",
            str(out / "session"),
        ],
        capture_output=True,
        text=True,
        timeout=600,
    )
    log = (out / "demo_nodes.log").read_text() if (out / "demo_nodes.log").exists() else ""
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-2000:] + log[-3000:]
    with open(out / "demo_field_map.csv", newline="") as file:
        return Demo(run.stdout, list(csv.DictReader(file)), log, out)


def test_every_ring_down_fits(demo):
    failed = [line for line in demo.log.splitlines() if "ring-down fit:" in line]
    assert not failed, "\n".join(failed)


def test_every_probe_is_decomposed(demo):
    stdout, rows = demo.stdout, demo.rows
    assert sorted({int(row["probe_id"]) for row in rows}) == [0, 1, 2]
    assert len(rows) == 15
    # How long the map took after the last fit is said (a figure, not a requirement here:
    # mows bench latency reports it).
    assert re.search(r"the field map came \d+\.\d s after the last ring-down's fit", stdout), stdout[-2000:]


def test_each_probe_is_mapped_without_its_neighbours_fields(demo):
    # The neighbours' field at 5 cm is 1.4 µT, their gradient 0.04 mT/m: taken for the probe's
    # own, or with ring-downs taken to start from the housing stop, the map is off by more.
    stdout, rows = demo.stdout, demo.rows
    error = np.array([float(row["value"]) - float(row["truth"]) for row in rows])
    field = np.array([row["quantity"].startswith("b") for row in rows])
    assert np.all(np.abs(error[field]) < 0.4e-6), stdout[-2000:]
    assert np.all(np.abs(error[~field]) < 0.15e-3), stdout[-2000:]


def test_each_probes_field_and_gradient_lie_within_their_sigma(demo):
    stdout, rows = demo.stdout, demo.rows
    pulls = np.array([float(row["pull"]) for row in rows])
    assert np.all(np.isfinite(pulls)), stdout[-2000:]
    assert np.sum(np.abs(pulls) <= 2.0) >= 12, stdout[-2000:]
    assert np.max(np.abs(pulls)) < 5.0, stdout[-2000:]


def test_the_recorded_session_replays_to_the_map_the_graph_published(demo, capsys):
    sections = yaml.safe_load((demo.out / "demo_parameters.yaml").read_text())
    mapper, estimator = (sections[f"/**/{name}"]["ros__parameters"] for name in ("mapper", "estimator"))
    bag = demo.out / "session"
    (published, *_) = [item.message for item in read_bag(bag, topics=["/mows/field_map"])][-1:]
    geometry = ["--sensor-distance-m", str(estimator["sensor_distance_m"]), "--sensor-spacing-m"]
    geometry += [str(estimator["sensor_spacing_m"]), "--sensor-direction", *map(str, estimator["sensor_direction"])]
    fits = [item.message for item in read_bag(bag, topics=["/mows/ringdown"])]
    lost = sum(f.status_name != "OK" for f in fits)  # by the live estimator (a gap), not by the bag
    for refit, bound_sigmas in ((False, 1e-6), (True, 0.05 if lost == 0 else 1.0)):
        command = ["map", str(bag), "--probes", mapper["probes"], "--probe", mapper["probe_file"], "--json"]
        assert main(command + (["--refit", *geometry] if refit else [])) == 0
        (sweep,) = json.loads(capsys.readouterr().out)["sweeps"]
        assert sweep["ok"], sweep["message"]
        for probe, replayed in zip(published.probes, sweep["maps"], strict=True):
            assert replayed["probe_id"] == probe.probe_id
            for name, std in (("field_t", "field_covariance_t2"), ("gradient_t_per_m", "gradient_covariance")):
                sigma = np.sqrt(np.diag(np.reshape(getattr(probe, std), (len(getattr(probe, name)),) * 2)))
                pulls = (np.array(replayed[name]) - np.array(getattr(probe, name))) / sigma
                assert np.all(np.abs(pulls) <= bound_sigmas), (refit, lost, probe.probe_id, name, pulls)
