"""One recording holds what the graph concludes: a driver recording while the estimator and the
mapper run a sweep writes, beside its stream, every fit the estimator published, the sweep's
decomposition, and /diagnostics; `mows lab compare BAG` then analyses that bag from its
recorded fits, without the graph, and `mows map BAG` makes the sweep again from them: the
decomposition the mapper published, to 1e-6σ."""

import json
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray

from mows.cli.main import main
from mows.device.recording import bags
from mows_bringup.graph import NODES
from node_processes import log

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

QUICK = ["-p", "tuning_steps:=1", "-p", "gap_s:=0.2", "-p", "turn_settle_s:=0.2", "-p", "ringdown_s:=0.5"]
BOUND_S = 420.0  # a hang's bound only


def test_a_recording_holds_the_fits_the_sweep_and_the_diagnostics(ros, start, tmp_path, capsys):
    bag = tmp_path / "session"
    nodes = {node.name: node for node in NODES}
    driver = start(*nodes["driver"].command([*QUICK, "-p", f"record_path:={bag}"]))
    others = [start(*nodes[name].command([])) for name in ("estimator", "mapper")]
    client = subprocess.run(
        [sys.executable, str(Path(__file__).with_name("sweep_client.py")), "0,72,144,216,288", "2", str(BOUND_S)],
        capture_output=True,
        text=True,
        timeout=BOUND_S + 60,
    )
    assert client.returncode == 0, (client.stderr, log(driver), *(log(p) for p in others))
    outcome = json.loads(client.stdout.splitlines()[-1])
    assert outcome["success"], outcome["message"]
    # The driver reports twice more after the map was published: it has heard the map by then.
    reports = []
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics", lambda a: reports.extend(s for s in a.status if s.name == "/driver"), 10
    )
    ros.wait_for(lambda: len(reports) >= 2, "two reports of the driver", 30.0)
    driver.send_signal(signal.SIGTERM)
    ros.wait_for(lambda: driver.poll() is not None, "the driver to stop", 60.0)
    assert driver.returncode == 0, log(driver)

    recorded = {}
    for message in bags.read_bag(bag):
        recorded.setdefault(message.topic, []).append(message.message)
    # Every fit the estimator published, as the client heard them; the sweep's decomposition and map.
    fits = recorded["/mows/ringdown"]
    assert len(fits) == sum(outcome["fits"].values()) == outcome["ringdowns_announced"]
    (sweep,) = recorded["/mows/sweep"]
    assert sweep.n_points == outcome["n_points"] == 10
    assert len(recorded["/mows/field"]) == outcome["fits"]["OK"]  # (a field map is of several probes)
    assert {s.name for a in recorded["/diagnostics"] for s in a.status} >= {"/driver", "/estimator", "/mapper"}
    assert recorded["/mows/raw"] and recorded["/mows/excitation"]

    # The bag alone is enough for the lab: its recorded fits, each a row.
    capsys.readouterr()
    assert main(["lab", "compare", str(bag)]) == 0
    assert f"{outcome['fits']['OK']} rows" in capsys.readouterr().out

    # The bag alone makes the sweep again, as the mapper made it.
    assert main(["map", str(bag), "--json"]) == 0
    (replayed,) = json.loads(capsys.readouterr().out)["sweeps"][0]["maps"]
    assert replayed["points"] == sweep.n_points
    for name, covariance in (("field_t", "field_covariance_t2"), ("gradient_t_per_m", "gradient_covariance")):
        published = np.array(getattr(sweep, name))
        sigma = np.sqrt(np.diag(np.reshape(getattr(sweep, covariance), (published.size,) * 2)))
        assert np.all(np.abs(np.array(replayed[name]) - published) <= 1e-6 * sigma), (name, replayed[name], published)
