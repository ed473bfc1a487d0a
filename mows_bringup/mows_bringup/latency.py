"""mows-latency: how long after the last sample of a ring-down its fit is published, in the graph.

Starts the driver (simulated device) and the estimator, asks the driver for measurement
cycles (or, with ``--tracking``, switches on the driver's tracking mode and takes its
ring-downs as they come), and, for every RingdownFit, takes the time at which this process received it minus
the time at which it received the raw block holding the ring-down's last sample (both on this
host's monotonic clock, so transport both ways is included). Prints the figures, or one JSON
object with ``--json`` (used by ``mows bench``). A benchmark: it reports, it never fails on a
figure.

``--duration S`` runs cycles back to back for S seconds instead of ``--cycles``; ``--load``
(60 s unless ``--duration`` says otherwise) runs them beside ``--burners`` CPU burners (two unless
said) and a 1 kHz JointState loop (``mows_bringup.load``), and adds the load as run to the figures. ``startup_s`` is
the time from starting the two processes to both active (bring-up included). Either way the
figures say how many gaps the estimator found in the raw stream (runs of lost blocks, from its
/diagnostics), how many this process found (``listener_gaps``: each subscriber loses its own),
and how many fits the estimator refused for a gap.
"""

import argparse
import collections
import json
import sys
import time

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from mows_msgs.msg import MagnetometerBlock, RingdownFit
from mows_msgs.srv import RunCycle

from mows.records import stamps
from mows_bringup.graph import Graph, add_realtime_option, say
from mows_bringup.load import Load
from mows_bringup.nodes import NODES
from mows_ros.diagnostics import DIAGNOSTICS_DEPTH, DIAGNOSTICS_TOPIC
from mows_ros.qos import RESULT_QOS, STREAM_QOS

LOAD_DURATION_S = 60.0  # the stream under load
REFUSED_PAUSE_S = 0.5  # before asking again for a cycle the driver refused


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="mows-latency", description=__doc__.splitlines()[0])
    parser.add_argument("--cycles", type=int, default=4, help="measurement cycles (each with --repeats ring-downs)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--tracking", action="store_true", help="the driver's tracking mode: cycles × repeats of its ring-downs"
    )
    parser.add_argument("--duration", type=float, help="run cycles back to back for this many seconds instead")
    parser.add_argument("--load", action="store_true", help="beside CPU burners and a 1 kHz JointState loop")
    parser.add_argument("--burners", type=int, default=2, help="with --load: how many CPU burners (default 2)")
    parser.add_argument(
        "--burner-nice",
        type=int,
        default=0,
        help="the burners' niceness (0: the graph's priority; 19: a smoke run that leaves other work its cores)",
    )
    add_realtime_option(parser)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    duration_s = args.duration if args.duration is not None else (LOAD_DURATION_S if args.load else None)
    load = Load(burners=args.burners, burner_nice=args.burner_nice) if args.load else None
    log = open("/dev/null", "w")
    mode = (
        ["-p", "driver:tracking:=true"]
        if args.tracking
        else ["-p", "driver:tuning_steps:=0", "-p", "driver:gap_s:=0.1"]
    )
    path = tuple(n for n in NODES if n.name in ("driver", "estimator"))
    graph = Graph(path, mode, output=log, realtime_priority=args.realtime_priority)
    started = time.monotonic()
    graph.start()
    if load is not None:
        load.start()
    try:
        problem = graph.bring_up()
        if problem is not None:
            say(f"bring-up failed: {problem}")
            return 1
        startup_s = time.monotonic() - started
        stream = measure(args.cycles, args.repeats, duration_s, graph.exited, args.tracking)
    finally:
        load_as_run = load.stop() if load is not None else None
        graph.stop()
    figures = {
        "mode": "tracking" if args.tracking else "cycles",
        "realtime_priority": args.realtime_priority,
        # from starting the processes to both active: imports, numba's cache (make build fills
        # it), configure; what a robot's launch waits for
        "startup_s": startup_s,
    }
    figures.update(summary(stream.latencies()))
    figures.update(stream.counts())
    if load_as_run is not None:
        figures["load"] = load_as_run
    if args.json:
        print(json.dumps(figures))
    else:
        for key, value in figures.items():
            say(f"{key:28s} {value:.3f}" if isinstance(value, float) else f"{key:28s} {value}")
    return 0 if figures["ringdowns"] else 1


class Stream:
    """What this process hears: when each raw block arrived (keyed by its device-time span), the
    gaps between blocks, every fit with its arrival time, and the estimator's last diagnostics."""

    def __init__(self):
        self.block_arrivals = {}  # (start s, stop s) → receive time
        self.fits = []
        self.gaps = 0
        self.missing_samples = 0
        self.cycles = 0
        self.ringdowns_recorded = 0
        self.refusals = collections.Counter()  # by the driver's reason
        self.cycles_s = 0.0  # from asking for the first cycle to the end of the last one asked for
        self._next_index = None
        self.estimator = {}
        self.ready = float("inf")  # when the estimator listened: ring-downs ended before are a backlog

    def on_block(self, block) -> None:
        self.block_arrivals[_block_key(block)] = time.monotonic()
        n = len(block.channels[0].field_t) if block.channels else 0
        if self._next_index is not None and block.first_sample_index > self._next_index:
            self.gaps += 1
            self.missing_samples += block.first_sample_index - self._next_index
        self._next_index = max(self._next_index or 0, block.first_sample_index + n)

    def on_cycle(self, response) -> bool:
        """A RunCycle answer; whether the cycle ran."""
        if response.success:
            self.cycles += 1
            self.ringdowns_recorded += response.ringdowns_recorded
        else:
            self.refusals[response.message] += 1
        return response.success

    def on_fit(self, fit) -> None:
        self.fits.append((time.monotonic(), fit))

    def on_diagnostics(self, array) -> None:
        for status in array.status:
            if status.name.endswith("/estimator"):
                self.estimator = {kv.key: kv.value for kv in status.values}

    def estimator_counted_every_fit(self) -> bool:
        fits = [self.estimator.get(key) for key in ("fits_ok", "fits_failed")]
        return None not in fits and sum(int(n) for n in fits) >= len(self.fits)

    def latencies(self) -> list:
        """(latency s, status) of every fit whose ring-down ended after the estimator listened."""
        ended = [(received, _last_sample_arrival(self.block_arrivals, fit), fit.status) for received, fit in self.fits]
        return [(received - last, status) for received, last, status in ended if last >= self.ready]

    def counts(self) -> dict:
        return {
            "cycles": self.cycles,
            "cycles_refused": dict(self.refusals),
            "cycles_s": self.cycles_s,
            "blocks": len(self.block_arrivals),
            "gaps": _count(self.estimator.get("gaps")),
            "missing_samples": _count(self.estimator.get("missing_samples")),
            "listener_gaps": self.gaps,
            "listener_missing_samples": self.missing_samples,
            "fits": len(self.fits),
            "fits_data_gap": sum(fit.status == RingdownFit.STATUS_DATA_GAP for _, fit in self.fits),
        }


def measure(cycles: int, repeats: int, duration_s: float | None, exited, tracking: bool = False) -> Stream:
    """``cycles`` cycles of ``repeats`` ring-downs, or as many as ``duration_s`` holds; with
    ``tracking``, cycles × repeats of the tracking mode's ring-downs."""
    rclpy.init()
    node = rclpy.create_node("mows_latency")
    stream = Stream()
    node.create_subscription(MagnetometerBlock, "mows/raw", stream.on_block, STREAM_QOS)
    node.create_subscription(RingdownFit, "mows/ringdown", stream.on_fit, RESULT_QOS)
    node.create_subscription(DiagnosticArray, DIAGNOSTICS_TOPIC, stream.on_diagnostics, DIAGNOSTICS_DEPTH)
    client = node.create_client(RunCycle, "driver/run_cycle")
    try:
        # The first cycle once the estimator hears the stream (its /diagnostics count blocks):
        # discovery takes seconds on a loaded machine, and a ring-down over before the
        # estimator's first block is counted by it, not fitted.
        _spin_until(
            node,
            lambda: client.service_is_ready() and stream.block_arrivals and int(stream.estimator.get("blocks", 0)),
            exited,
            120.0,
        )
        # Tracking runs from the driver's start: ring-downs that ended before the estimator
        # listened are a start-up backlog, not the graph's latency, and are left out.
        stream.ready = started = time.monotonic()
        if tracking:
            wanted = len(stream.fits) + cycles * repeats
            _spin_until(node, lambda: len(stream.fits) >= wanted, exited, 120.0)
        end = None if duration_s is None else started + duration_s
        asked = 0
        while not tracking and ((asked < cycles) if end is None else (time.monotonic() < end)):
            future = client.call_async(RunCycle.Request(theta0_rad=0.0, repeats=repeats, tuning_steps=-1, gap_s=-1.0))
            _spin_until(node, future.done, exited, 120.0)
            asked += 1
            if not stream.on_cycle(future.result()):  # refused (the coils' duty-cycle cap): let them cool
                _spin_for(node, REFUSED_PAUSE_S, exited)
            stream.cycles_s = time.monotonic() - started
        _spin_until(node, lambda: len(stream.fits) >= stream.ringdowns_recorded, exited, 30.0)
        _spin_until(node, stream.estimator_counted_every_fit, exited, 30.0)
    except TimeoutError as error:
        say(str(error))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return stream


def _count(text: str | None) -> int | None:
    """A count from /diagnostics; None when the estimator's diagnostics never came."""
    return None if text is None else int(text)


def _block_key(block):
    start = stamps.seconds(block.header.stamp)
    n = len(block.channels[0].field_t) if block.channels else 0
    return (start, start + n / block.sample_rate_hz)


def _last_sample_arrival(arrivals: dict, fit) -> float:
    """Receive time of the block that holds the last sample of the fitted window."""
    end = stamps.seconds(fit.header.stamp) + fit.duration_s
    holding = [t for (start, stop), t in arrivals.items() if start <= end - 1e-9 < stop + 1e-9]
    return min(holding) if holding else float("nan")


def _spin_for(node, duration_s, exited):
    end = time.monotonic() + duration_s
    _spin_until(node, lambda: time.monotonic() >= end, exited, 2 * duration_s + 1.0)


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
