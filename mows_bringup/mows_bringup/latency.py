"""mows-latency: how long after the last sample of a ring-down its fit is published, in the graph.

Starts the driver (simulated device) and the estimator, asks the driver for measurement
cycles (or, with ``--tracking``, switches on the driver's tracking mode and takes its
ring-downs as they come), and, for every RingdownFit, takes the time at which this process received it minus
the time at which it received the raw block holding the ring-down's last sample (both on this
host's monotonic clock, so transport both ways is included). Prints the figures, or one JSON
object with ``--json`` (used by ``mows bench``). A benchmark: it reports, it never fails on a
figure.
"""

import argparse
import json
import sys
import time

import numpy as np
import rclpy
from mows_msgs.msg import MagnetometerBlock, RingdownFit
from mows_msgs.srv import RunCycle

from mows.records import stamps
from mows_bringup.graph import NODES, Graph, say
from mows_ros.qos import RESULT_QOS, STREAM_QOS


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="mows-latency", description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=4, help="measurement cycles (each with --repeats ring-downs)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--tracking", action="store_true", help="the driver's tracking mode: cycles × repeats of its ring-downs"
    )
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    log = open("/dev/null", "w")
    mode = (
        ["-p", "driver:tracking:=true"]
        if args.tracking
        else ["-p", "driver:tuning_steps:=0", "-p", "driver:gap_s:=0.1"]
    )
    graph = Graph(tuple(n for n in NODES if n.name in ("driver", "estimator")), mode, output=log)
    graph.start()
    try:
        latencies = measure(args.cycles, args.repeats, graph.exited, args.tracking)
    finally:
        graph.stop()
    figures = {"mode": "tracking" if args.tracking else "cycles", **summary(latencies)}
    if args.json:
        print(json.dumps(figures))
    else:
        for key, value in figures.items():
            say(f"{key:28s} {value:.3f}" if isinstance(value, float) else f"{key:28s} {value}")
    return 0 if latencies else 1


def measure(cycles: int, repeats: int, exited, tracking: bool = False) -> list:

    rclpy.init()
    node = rclpy.create_node("mows_latency")
    block_arrivals = {}  # stop sample index → (receive time, first sample stamp, rate)
    fits = []
    node.create_subscription(
        MagnetometerBlock, "mows/raw", lambda b: block_arrivals.__setitem__(_block_key(b), time.monotonic()), STREAM_QOS
    )
    node.create_subscription(RingdownFit, "mows/ringdown", lambda f: fits.append((time.monotonic(), f)), RESULT_QOS)
    client = node.create_client(RunCycle, "mows/driver/run_cycle")
    ready = wanted = float("inf")
    try:
        # The estimator advertises its fits once it listens (after its kernels are compiled):
        # a cycle run before would reach it through the latched excitation states only, late.
        _spin_until(
            node,
            lambda: client.service_is_ready() and block_arrivals and node.count_publishers("/mows/ringdown") > 0,
            exited,
            120.0,
        )
        # Tracking runs from the driver's start: ring-downs that ended before the estimator
        # listened are a start-up backlog, not the graph's latency, and are left out.
        ready = time.monotonic()
        wanted = len(fits) + cycles * repeats
        for _ in range(0 if tracking else cycles):
            future = client.call_async(RunCycle.Request(theta0_rad=0.0, repeats=repeats, tuning_steps=-1, gap_s=-1.0))
            _spin_until(node, future.done, exited, 120.0)
        _spin_until(node, lambda: len(fits) >= wanted, exited, 120.0 if tracking else 30.0)
    except TimeoutError as error:
        say(str(error))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    ended = [(received, _last_sample_arrival(block_arrivals, fit), fit.status) for received, fit in fits]
    return [(received - last, status) for received, last, status in ended if last >= ready]


def _block_key(block):
    start = stamps.seconds(block.header.stamp)
    n = len(block.channels[0].field_t) if block.channels else 0
    return (start, start + n / block.sample_rate_hz)


def _last_sample_arrival(arrivals: dict, fit) -> float:
    """Receive time of the block that holds the last sample of the fitted window."""
    end = stamps.seconds(fit.header.stamp) + fit.duration_s
    holding = [t for (start, stop), t in arrivals.items() if start <= end - 1e-9 < stop + 1e-9]
    return min(holding) if holding else float("nan")


def _spin_until(node, condition, exited, timeout_s):

    deadline = time.monotonic() + timeout_s
    while not condition():
        if exited() or time.monotonic() > deadline:
            raise TimeoutError(f"gave up waiting (nodes ended: {exited()})")
        rclpy.spin_once(node, timeout_sec=0.05)


def summary(latencies) -> dict:
    """Figures of the OK fits; ``failed_fits``: fits with another status (not timed)."""
    values = np.array([v for v, status in latencies if status == 0 and np.isfinite(v)]) * 1e3
    failed = sum(status != 0 for _, status in latencies)
    if values.size == 0:
        return {"ringdowns": 0, "failed_fits": failed}
    return {
        "ringdowns": int(values.size),
        "failed_fits": failed,
        "latency_ms_median": float(np.median(values)),
        "latency_ms_p99": float(np.percentile(values, 99)),
        "latency_ms_max": float(values.max()),
        "goal_p99_ms": 20.0,
    }


if __name__ == "__main__":
    sys.exit(main())
