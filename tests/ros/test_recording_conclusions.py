"""One recording holds what the graph concludes: the driver recording (`make demo --record`,
the driver's ``record_path``) while the estimator and the mapper run a sweep writes, beside its
stream, every fit the estimator published, the sweep's decomposition, and /diagnostics; `mows lab
compare BAG` then analyses that bag from its recorded fits, without the graph, and `mows map
BAG` makes the sweep again from them: the decomposition the mapper published, to 1e-6σ.

The recording is the demo run of the ``demo_session`` fixture, whose printout
tests/ros/test_readme_demo.py checks."""

import json
import re

import numpy as np
import pytest
import yaml

from mows.cli.main import main
from mows.device.recording import bags
from mows.records import stamps

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

ORIENTATIONS = 6  # the demo_session's sweep, one ring-down each


def test_a_recording_holds_the_fits_the_sweep_and_the_diagnostics(demo_session, capsys):
    recorded = {}
    for message in bags.read_bag(demo_session.bag):
        recorded.setdefault(message.topic, []).append(message.message)
    # Every fit the estimator published, as the demo's sweep client heard them: per orientation
    # "(k of n ring-downs OK)".
    heard = [re.search(r"\((\d+) of (\d+) ring-downs OK\)", line) for line in demo_session.lines]
    heard = [(int(m[1]), int(m[2])) for m in heard if m]
    ok = sum(k for k, _ in heard)
    assert len(heard) == ORIENTATIONS and sum(n for _, n in heard) == ORIENTATIONS, demo_session.lines
    fits = recorded["/mows/ringdown"]
    assert len(fits) == ORIENTATIONS and sum(f.status_name == "OK" for f in fits) == ok
    (sweep,) = recorded["/mows/sweep"]
    assert sweep.n_points == ok
    assert len(recorded["/mows/field"]) == ok  # (a field map is of several probes)
    assert {s.name for a in recorded["/diagnostics"] for s in a.status} >= {"/driver", "/estimator", "/mapper"}
    assert recorded["/mows/raw"] and recorded["/mows/excitation"]

    # The bag alone is enough for the lab: its recorded fits, each a row.
    capsys.readouterr()
    assert main(["lab", "compare", str(demo_session.bag)]) == 0
    assert f"{ok} rows" in capsys.readouterr().out

    # The bag alone makes the sweep again, as the mapper made it (with the probe file it loaded).
    sections = yaml.safe_load((demo_session.out / "demo_parameters.yaml").read_text())
    probe_file = sections["/**/mapper"]["ros__parameters"]["probe_file"]
    assert main(["map", str(demo_session.bag), "--probe", probe_file, "--json"]) == 0
    (replayed,) = json.loads(capsys.readouterr().out)["sweeps"][0]["maps"]
    assert replayed["points"] == sweep.n_points
    for name, covariance in (("field_t", "field_covariance_t2"), ("gradient_t_per_m", "gradient_covariance")):
        published = np.array(getattr(sweep, name))
        sigma = np.sqrt(np.diag(np.reshape(getattr(sweep, covariance), (published.size,) * 2)))
        assert np.all(np.abs(np.array(replayed[name]) - published) <= 1e-6 * sigma), (name, replayed[name], published)


def test_a_recording_holds_the_stage_so_its_view_has_the_mount_s_frames(demo_session, capsys):
    from mcap.reader import make_reader

    recorded = {}
    for message in bags.read_bag(demo_session.bag, ["/mows/raw", "/mows/joint_states", "/mows/ringdown"]):
        recorded.setdefault(message.topic, []).append(message.message)
    # The stage's angle with every block, once the first cycle has made it known (the last
    # block's too, when the shutdown stopped the publishing after its block was recorded).
    joints = [stamps.nanoseconds(m.header.stamp) for m in recorded["/mows/joint_states"]]
    blocks = [stamps.nanoseconds(m.header.stamp) for m in recorded["/mows/raw"]]
    assert joints and joints == [stamp for stamp in blocks if stamp >= joints[0]]
    assert main(["viz", str(demo_session.bag), "--mount", "mows_bringup/urdf/mows_probe_mount.urdf"]) == 0
    output = demo_session.bag.parent / f"{demo_session.bag.name}.view.mcap"
    with open(output, "rb") as stream:
        counts: dict[str, int] = {}
        for _, channel, _ in make_reader(stream).iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts.get("/mows/viz/frames", 0) == len(recorded["/mows/joint_states"])
    # Every OK fit drawn, none dropped.
    assert counts.get("/mows/viz/ringdown", 0) == sum(f.status_name == "OK" for f in recorded["/mows/ringdown"])


def test_a_viewer_connected_through_the_demo_got_every_fit_of_the_recording_drawn(demo_session):
    # The live view draws each OK fit the estimator published, which the bag holds, over all of
    # its samples: none dropped, none drawn over samples the stream had not yet brought.
    fits = [m.message for m in bags.read_bag(demo_session.bag, ["/mows/ringdown"]) if m.message.status_name == "OK"]
    assert len(fits) == ORIENTATIONS
    plots = [json.loads(data) for data in demo_session.live.payloads("/mows/viz/ringdown")]
    drawn = {(p["cycle_id"], p["repeat_index"], p["probe_id"]): p for p in plots}
    assert sorted(drawn) == sorted((f.cycle_id, f.repeat_index, f.probe_id) for f in fits), demo_session.lines[-40:]
    for fit in fits:
        plot = drawn[(fit.cycle_id, fit.repeat_index, fit.probe_id)]
        assert plot["frequency_hz"] == fit.frequency_hz
        data = np.array(plot["data_t"], float)
        assert np.all(np.isfinite(data)), (fit.cycle_id, int(np.isnan(data).sum()), data.size)
