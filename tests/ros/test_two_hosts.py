"""Two hosts: the driver in one Linux network namespace (the sensor computer), the estimator,
the mapper and a sweep client in another (the robot computer), joined only by a veth pair.
DDS discovers across the link (ROS_AUTOMATIC_DISCOVERY_RANGE=SUBNET with ROS_STATIC_PEERS; UDP
only, so shared memory cannot bypass the link), and a sweep completes.

Then over a lossy link: 5 % of the UDP datagrams leaving either end of the veth pair dropped at
random, and each of them delayed by 20 ms too. ``tc netem`` would do both, but
kernels without sch_netem (or sch_fq) exist, this machine's among them ("Specified qdisc kind is
unknown"): the loss is an nftables rule (``numgen random mod 100 < 5 drop``, on the veth only)
and the delay an iptables NFQUEUE rule with ``delay_link.py`` giving the verdicts 20 ms late.
Lost raw blocks must be counted as gaps, every fit over one refused (DATA_GAP, no numbers) and
kept out of the map, the reliable fits all delivered and counted alike on both sides, the sweep
action answered, and /diagnostics must report the loss. Where no netfilter queue can be had,
the link only loses datagrams, and the test says that the delay was not tested and why. (The
loss alone is not run beside the loss with the delay: the same sweep, the same checks, a
minute more of the suite.)

Skipped, saying so, where network namespaces cannot be created (not root, no iproute2)."""

import json
import os
import re
import shutil
import subprocess
import sys
import time
import warnings
from pathlib import Path

import pytest
from diagnostic_msgs.msg import DiagnosticStatus

from mows_bringup.nodes import NODES
from node_processes import log

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

SENSOR, ROBOT = "10.78.0.1", "10.78.0.2"
PREFIX = "/24"
BOUND_S = 420.0  # a hang's bound only, inside pytest's timeout (600 s) so that the client says what it waited for
QUICK = ["-p", "tuning_steps:=1", "-p", "gap_s:=0.2", "-p", "turn_settle_s:=0.2"]
LOSS_PERCENT = 5
DELAY_MS = 20
# Over the lossy link with the delay, 15 of 24 ring-downs of 0.25 s had a gap in one run (63 %;
# a lost raw block may be several datagrams). At 63 % and 5 repeats an orientation has no clean
# ring-down with probability 0.63^5 = 10 %, so 8 orientations leave fewer than the 5 a
# decomposition needs with probability 0.4 % (3 repeats: 11 %).
LOSSY = [*QUICK, "-p", "ringdown_s:=0.25"]
DELAY_LINK = Path(__file__).with_name("delay_link.py")
LOSSY_ANGLES, LOSSY_REPEATS = "0,45,90,135,180,225,270,315", "5"


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


def sweep(hosts, start, driver_args, angles="0,72,144,216,288", repeats="1") -> dict:
    """The driver on the sensor host, the estimator, the mapper and a sweep client on the robot
    host; the client's outcome (sweep_client.py)."""
    nodes = {node.name: node for node in NODES}
    driver = start(*inside(hosts["sensor"], *nodes["driver"].command(driver_args)))
    others = [start(*inside(hosts["robot"], *nodes[name].command([]))) for name in ("estimator", "mapper")]
    client = subprocess.run(
        inside(
            hosts["robot"],
            sys.executable,
            str(Path(__file__).with_name("sweep_client.py")),
            angles,
            repeats,
            str(BOUND_S),
        ),
        capture_output=True,
        text=True,
        timeout=BOUND_S + 60,
    )
    logs = (client.stderr, log(driver), *(log(p) for p in others))
    assert client.returncode == 0, logs
    # A node never dies on data, lost or late.
    assert driver.poll() is None and all(p.poll() is None for p in others), logs
    return json.loads(client.stdout.splitlines()[-1])


def test_a_sweep_runs_with_the_driver_on_another_host(hosts, start):
    assert ip("-n", hosts["sensor"][0], "addr", "show").stdout.count("inet 10.78.") == 1
    outcome = sweep(hosts, start, QUICK)
    assert outcome["accepted"] and outcome["success"], outcome["message"]
    assert outcome["n_points"] == 5
    # The robot host heard the sensor host's stream and diagnostics, across the link only.
    assert outcome["blocks_heard"] > 0 and int(outcome["estimator"]["blocks"]) > 0
    assert outcome["driver"]["link_up"] == "True" and outcome["driver"]["link"] == "simulated"


def drop_at_random(hosts) -> None:
    """Both ends of the veth pair drop ``LOSS_PERCENT`` % of the UDP datagrams they send, counted."""
    assert shutil.which("nft"), "nft not found: install nftables (make test does)"
    for namespace, _, _ in hosts.values():
        rules = f"""
            table inet mows_loss {{
                chain out {{
                    type filter hook output priority 0; policy accept;
                    oifname "{namespace}v" meta l4proto udp numgen random mod 100 < {LOSS_PERCENT} counter drop
                }}
            }}"""
        done = subprocess.run(
            ["ip", "netns", "exec", namespace, "nft", "-f", "-"], input=rules, capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr


def dropped(hosts) -> int:
    """Datagrams the loss rules dropped, both ends."""
    total = 0
    for namespace, _, _ in hosts.values():
        listing = subprocess.run(
            ["ip", "netns", "exec", namespace, "nft", "list", "table", "inet", "mows_loss"],
            capture_output=True,
            text=True,
        ).stdout
        total += sum(int(n) for n in re.findall(r"counter packets (\d+)", listing))
    return total


def delay(hosts, start) -> list | str:
    """``DELAY_MS`` ms on every UDP datagram leaving either end (delay_link.py behind a netfilter
    queue): the handlers, or why the delay cannot be made here."""
    handlers = []
    for namespace, _, _ in hosts.values():
        handler = start("ip", "netns", "exec", namespace, sys.executable, str(DELAY_LINK), "0", str(DELAY_MS))
        deadline = time.monotonic() + 60.0  # a hang's bound only
        while "bound" not in log(handler) and handler.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        if "bound" not in log(handler):
            return f"no netfilter queue to delay packets in: {log(handler).strip()[-300:]}"
        rule = f"-A OUTPUT -o {namespace}v -p udp -j NFQUEUE --queue-num 0".split()
        done = subprocess.run(["ip", "netns", "exec", namespace, "iptables", *rule], capture_output=True, text=True)
        if done.returncode != 0:
            return f"iptables cannot queue packets: {done.stderr.strip()}"
        handlers.append(handler)
    return handlers


def delayed(handlers) -> int:
    """Packets the handlers delayed (they say so when they stop)."""
    for handler in handlers:
        handler.terminate()
        handler.wait(timeout=30)
    return sum(int(re.search(r"delayed (\d+)", log(h)).group(1)) for h in handlers)


def test_a_sweep_over_a_lossy_link(hosts, start):
    drop_at_random(hosts)
    handlers = delay(hosts, start)
    if isinstance(handlers, str):
        warnings.warn(f"{DELAY_MS} ms delay not tested ({handlers}); the loss alone is", stacklevel=1)
        handlers = []
    outcome = sweep(hosts, start, LOSSY, LOSSY_ANGLES, LOSSY_REPEATS)
    estimator, fits = outcome["estimator"], outcome["fits"]
    lost, held = dropped(hosts), delayed(handlers)
    print(f"{lost} datagrams dropped, {held} delayed {DELAY_MS} ms; fits {fits}; ")
    print(f"estimator gaps {estimator['gaps']}, missing samples {estimator['missing_samples']}; {outcome['message']}")
    assert lost > 0 and (held > 0 or not handlers)
    # Lost raw blocks are counted as gaps, and reported on /diagnostics with a warning.
    assert int(estimator["gaps"]) > 0 and int(estimator["missing_samples"]) > 0, estimator
    assert estimator["level"] == ord(DiagnosticStatus.WARN)
    # Every fit over a gap is refused and carries no numbers; nothing else failed.
    assert fits.get("DATA_GAP", 0) > 0 and set(fits) <= {"OK", "DATA_GAP"}, fits
    assert outcome["failed_fits_with_numbers"] == 0
    # The reliable fits all arrived: the estimator's counts (on /diagnostics, reliable too) are the client's.
    assert int(estimator["fits_ok"]) == fits.get("OK", 0) and int(estimator["status_DATA_GAP"]) == fits["DATA_GAP"]
    ringdowns = len(LOSSY_ANGLES.split(",")) * int(LOSSY_REPEATS)
    assert outcome["ringdowns_announced"] == int(estimator["fits_ok"]) + int(estimator["fits_failed"]) == ringdowns
    # The action answered, the sweep decomposed, and its map holds clean fits only. (Not always all
    # of them: in 1 of 7 runs with the delay the map had 13 points of 14 OK fits; why is not known.)
    assert outcome["accepted"] and outcome["success"], outcome["message"]
    assert 5 <= outcome["n_points"] <= fits["OK"]
