"""Two hosts: the driver in one Linux network namespace (the sensor computer), the estimator,
the mapper and a sweep client in another (the robot computer), joined only by a veth pair.
DDS discovers across the link (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET with ROS_STATIC_PEERS; UDP
only, so shared memory cannot bypass the link), and a sweep completes.

Skipped, saying so, where network namespaces cannot be created (not root, no iproute2)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from mows_bringup.graph import NODES
from node_processes import log

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

SENSOR, ROBOT = "10.78.0.1", "10.78.0.2"
PREFIX = "/24"
BOUND_S = 600.0  # a hang's bound only
QUICK = ["-p", "tuning_steps:=1", "-p", "gap_s:=0.2", "-p", "settle_s:=0.2"]


def ip(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["ip", *args], capture_output=True, text=True)


@pytest.fixture
def hosts():
    """Two namespaces joined by a veth pair: {name: (namespace, own address, peer address)}."""
    tag = f"mows{os.getpid() % 100000}"
    sensor, robot = f"{tag}s", f"{tag}r"
    made = ip("netns", "add", sensor)
    if made.returncode != 0:
        pytest.skip(
            f"cannot create a network namespace here ({made.stderr.strip()}): the two-host test needs root and iproute2"
        )
    try:
        steps = [
            ("netns", "add", robot),
            ("link", "add", f"{sensor}v", "type", "veth", "peer", "name", f"{robot}v"),
            ("link", "set", f"{sensor}v", "netns", sensor),
            ("link", "set", f"{robot}v", "netns", robot),
        ]
        for ns, address in ((sensor, SENSOR), (robot, ROBOT)):
            steps += [
                ("-n", ns, "addr", "add", address + PREFIX, "dev", f"{ns}v"),
                ("-n", ns, "link", "set", "lo", "up"),
                ("-n", ns, "link", "set", f"{ns}v", "up", "multicast", "on"),
                ("-n", ns, "route", "add", "224.0.0.0/4", "dev", f"{ns}v"),
            ]
        for step in steps:
            done = ip(*step)
            assert done.returncode == 0, (step, done.stderr)
        yield {"sensor": (sensor, SENSOR, ROBOT), "robot": (robot, ROBOT, SENSOR)}
    finally:
        ip("netns", "del", sensor)
        ip("netns", "del", robot)


def inside(host, *command: str) -> list[str]:
    """``command`` run in ``host``'s namespace, finding its peer by address over UDP only."""
    namespace, _, peer = host
    return [
        "ip",
        "netns",
        "exec",
        namespace,
        "env",
        "ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET",
        f"ROS_STATIC_PEERS={peer}",
        "FASTDDS_BUILTIN_TRANSPORTS=UDPv4",
        *command,
    ]


def test_a_sweep_runs_with_the_driver_on_another_host(hosts, start):
    assert ip("-n", hosts["sensor"][0], "addr", "show").stdout.count("inet 10.78.") == 1
    nodes = {node.name: node for node in NODES}
    driver = start(*inside(hosts["sensor"], *nodes["driver"].command(QUICK)))
    others = [start(*inside(hosts["robot"], *nodes[name].command([]))) for name in ("estimator", "mapper")]
    client = subprocess.run(
        inside(
            hosts["robot"],
            sys.executable,
            str(Path(__file__).with_name("sweep_client.py")),
            "0,72,144,216,288",
            "1",
            str(BOUND_S),
        ),
        capture_output=True,
        text=True,
        timeout=BOUND_S + 60,
    )
    assert client.returncode == 0, (client.stderr, log(driver), *(log(p) for p in others))
    outcome = json.loads(client.stdout.splitlines()[-1])
    assert outcome["accepted"] and outcome["success"], outcome["message"]
    assert outcome["n_points"] == 5
    # The robot host heard the sensor host's stream and diagnostics, across the link only.
    assert outcome["blocks_heard"] > 0 and int(outcome["estimator"]["blocks"]) > 0
    assert outcome["driver"]["link_up"] == "True" and outcome["driver"]["link"] == "simulated"
