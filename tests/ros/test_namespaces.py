"""Two probes beside each other: two complete graphs (driver, estimator, mapper) in the
namespaces /probe_a and /probe_b of one domain, each simulating its own scene, run their
sweeps at the same time. Nothing crosses over: each sweep hears only its own ring-downs
(their orientations tell them apart) and recovers its own scene's field; /diagnostics names
all six nodes apart."""

import math
import signal

import numpy as np
import pytest
import yaml
from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.action import RotationSweep
from mows_msgs.msg import MagnetometerBlock, RingdownFit
from rclpy.action import ActionClient

from mows.lab import reference_at
from mows.sim.scenario import load_scenario
from mows_ros.qos import RESULT_QOS, STREAM_QOS
from node_processes import log

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

# Each probe its scene and its orientations (15° apart from the other's, so that a fit that
# reached the wrong mapper would show).
PROBES = {
    "/probe_a": ("helmholtz", np.radians(np.arange(0.0, 360.0, 60.0))),
    "/probe_b": ("anti_helmholtz", np.radians(np.arange(15.0, 375.0, 60.0))),
}
REPEATS = 2
BOUND_S = 600.0  # a hang's bound only: two sweeps of 6 orientations on two loaded cores


def parameters(path, scenario: str):
    """The probe's scene, and short cycles (one tuning ring-down, short pauses)."""
    path.write_text(
        yaml.safe_dump(
            {
                "/**/driver": {
                    "ros__parameters": {
                        "scenario": scenario,
                        "coil_setup": load_scenario(scenario).setup.name,
                        "tuning_steps": 1,
                        "gap_s": 0.2,
                        "turn_settle_s": 0.2,
                    }
                },
                "/**/mapper": {"ros__parameters": {"repeats_per_angle": REPEATS}},
            }
        )
    )
    return path


def test_two_probes_in_namespaces_sweep_at_once_without_cross_talk(ros, start, tmp_path):
    statuses = {}
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics", lambda a: statuses.update((s.name, s) for s in a.status), 10
    )
    graphs, clients, fits, blocks = {}, {}, {}, {}
    for namespace, (scenario, _) in PROBES.items():
        graphs[namespace] = start(
            "mows-graph",
            "--ros-args",
            "-r",
            f"__ns:={namespace}",
            "--params-file",
            str(parameters(tmp_path / f"{namespace[1:]}.yaml", scenario)),
        )
        clients[namespace] = ActionClient(ros.node, RotationSweep, f"{namespace}/mapper/rotation_sweep")
        fits[namespace], blocks[namespace] = [], []
        ros.node.create_subscription(MagnetometerBlock, f"{namespace}/mows/raw", blocks[namespace].append, STREAM_QOS)
        ros.node.create_subscription(RingdownFit, f"{namespace}/mows/ringdown", fits[namespace].append, RESULT_QOS)
    names = {f"{ns}/{node}" for ns in PROBES for node in ("driver", "estimator", "mapper")}
    ros.wait_for(lambda: names <= statuses.keys(), "diagnostics of all six nodes", BOUND_S)
    ros.wait_for(lambda: all(c.server_is_ready() for c in clients.values()), "both sweep actions", BOUND_S)
    ros.wait_for(lambda: all(blocks.values()), "both sample streams", BOUND_S)
    ros.wait_for(
        lambda: all(ros.node.count_publishers(f"{ns}/mows/ringdown") for ns in PROBES), "both estimators", BOUND_S
    )
    # The nodes are up (and report) before mows-graph activates them; a goal sent to a mapper
    # not yet active is refused, rightly.
    ros.wait_for(lambda: all("every node is active" in log(g) for g in graphs.values()), "both bring-ups", BOUND_S)

    sent = {
        ns: clients[ns].send_goal_async(RotationSweep.Goal(theta0_rad=angles.tolist(), repeats_per_angle=REPEATS))
        for ns, (_, angles) in PROBES.items()
    }
    handles = ros.wait_for(
        lambda: all(s.done() for s in sent.values()) and {ns: s.result() for ns, s in sent.items()},
        "both goals accepted",
        BOUND_S,
    )
    assert all(h.accepted for h in handles.values()), [log(g) for g in graphs.values()]
    results = {ns: h.get_result_async() for ns, h in handles.items()}
    done = ros.wait_for(
        lambda: all(r.done() for r in results.values()) and {ns: r.result() for ns, r in results.items()},
        "both sweeps",
        BOUND_S,
    )

    for namespace, (scenario, angles) in PROBES.items():
        outcome = done[namespace]
        assert outcome.status == GoalStatus.STATUS_SUCCEEDED, (
            namespace,
            outcome.result.message,
            log(graphs[namespace]),
        )
        d = outcome.result.decomposition
        assert d.n_points == REPEATS * len(angles)
        truth, _ = reference_at(scenario)
        sigma = np.sqrt(np.diag(np.reshape(d.field_covariance_t2, (2, 2))))
        assert np.all(np.abs(np.array(d.field_t) - truth[:2]) < 5 * sigma), (namespace, d.field_t, truth, sigma)
        measured = [f for f in fits[namespace] if not f.tuning]
        assert len(measured) >= REPEATS * len(angles)
        assert all(min(abs(math.remainder(f.theta0_rad - a, 2 * math.pi)) for a in angles) < 1e-9 for f in measured)
    # The two scenes differ by far more than either's uncertainty: the maps are not one map.
    a, b = (np.array(done[ns].result.decomposition.field_t) for ns in PROBES)
    assert np.linalg.norm(a - b) > 50e-6

    for graph in graphs.values():
        graph.send_signal(signal.SIGTERM)
    ros.wait_for(lambda: all(g.poll() is not None for g in graphs.values()), "both graphs to stop", BOUND_S)
    assert [g.returncode for g in graphs.values()] == [0, 0], [log(g) for g in graphs.values()]
