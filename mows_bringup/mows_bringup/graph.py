"""mows-graph: run the MOWS node graph without ``ros2 launch`` (not installed here).

    mows-graph [--duration S] [--unconfigured] [--realtime-priority N] [--foxglove[=PORT]]
               [--ros-args ARGS...]

Starts every node's console script with its parameter file (share/<package>/config/<node>.yaml)
and any ``--ros-args`` given here, prefixes each line a node writes with ``[node]``, and
forwards SIGINT and SIGTERM to the nodes. The nodes are managed (lifecycle) nodes: mows-graph
configures them all, then activates them in data-flow order (driver, estimator, mapper,
calibrator) through their lifecycle services; ``--unconfigured`` leaves them unconfigured for
a supervisor. ``--realtime-priority N`` runs the nodes on the ring-down path (driver and
estimator) under SCHED_FIFO at priority N, so that busy processes beside them (a robot stack's
planners, compilers) delay neither the stream nor the fits; a robot's own control loop, at a
higher priority, still preempts them. It needs root or an RLIMIT_RTPRIO of at least N.
``--foxglove[=PORT]`` also starts the viz node (mows_viz), which serves the graph to
Foxglove over its WebSocket protocol on PORT (default 8765; 0: any free port) with the probe
mount's frames (docs/visualisation.md); the address to open is printed. When the mapper or the
calibrator turns the probe by hand (``orientation: manual``), each line typed into this
terminal (Enter) confirms the turn a node awaits, as ``mows-confirm-orientation`` does.

Exit status: 0 when the graph was stopped (by a signal or after --duration) and
every node stopped cleanly; 2 when the ROS arguments are refused before any node starts (a
parameter without a node's prefix, a prefix or a name no node has, a parameter file that
is none; ROS's own parameters, such as ``use_sim_time``, may be given with or without a
node's prefix; a driver backend that cannot turn the stage, nidaqmx, without
``-p mapper:orientation:=manual -p calibrator:orientation:=manual``); 1 when a node refused a
transition, exited by itself or did not stop cleanly.
"""

import argparse
import ctypes
import os
import queue
import resource
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable

from mows_bringup.confirm import confirm_turn
from mows_bringup.lifecycle import BringUpError, bring_up
from mows_bringup.nodes import (
    FOXGLOVE_PORT,
    GraphNode,
    foxglove_arguments,
    graph_nodes,
    manual_turns,
    ros_arguments_problem,
    stage_problem,
)
from mows_ros.process import EXIT_BAD_PARAMETER

# A node still running this long after SIGINT is aborted. Its stop is a bound only, not a wait:
# the interpreter's teardown of a stopped node's modules takes 0.7 s on an idle host and stretches
# with the load (past 10 s for a calibrator on two cores under the full test suite).
STOP_TIMEOUT_S = 30.0
ABORT_TIMEOUT_S = 5.0  # and killed if it outlives the abort
PR_SET_PDEATHSIG = 1  # linux/prctl.h
_prctl = ctypes.CDLL(None, use_errno=True).prctl


def answer_turns_from(lines, ros_args: list[str]) -> threading.Thread:
    """Each line of ``lines`` (Enter in the terminal) confirms the turn a node awaits, as
    mows-confirm-orientation does; each node's answer is said."""

    def answer() -> None:
        for _ in lines:
            for line in confirm_turn(ros_args)[1]:
                say(line)

    thread = threading.Thread(target=answer, name="operator", daemon=True)  # a blocked read ends with the process
    thread.start()
    return thread


def say(text: str) -> None:
    sys.stdout.write(f"[graph] {text}\n")
    sys.stdout.flush()


def _child_setup(fifo_priority: int) -> Callable[[], None]:
    """What runs in a node's process between fork and exec."""

    def setup() -> None:
        # If mows-graph itself is killed, the kernel sends the node SIGTERM, which it handles
        # like a normal stop, instead of orphaning it.
        _prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        if fifo_priority:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(fifo_priority))

    return setup


def realtime_priority(text: str) -> int:
    """``--realtime-priority``'s value: 0 (off) or a SCHED_FIFO priority this process may give
    its nodes; argparse.ArgumentTypeError, with the reason, otherwise."""
    try:
        priority = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None
    low, high = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if priority and not low <= priority <= high:
        raise argparse.ArgumentTypeError(f"must be {low}–{high} (or 0: off), got {priority}")
    limit = resource.getrlimit(resource.RLIMIT_RTPRIO)[0]
    if priority and os.geteuid() != 0 and limit != resource.RLIM_INFINITY and limit < priority:
        raise argparse.ArgumentTypeError(
            f"{priority} needs root or an RLIMIT_RTPRIO of at least {priority} (now {limit})"
        )
    return priority


class Graph:
    """The running nodes, and one queue of what happens to them: ``(kind, who)`` events
    ``up`` (first line of output), ``exit`` and ``signal``. A SimpleQueue, because it is the
    queue that a signal handler may put into."""

    def __init__(self, nodes: tuple[GraphNode, ...], ros_args: list[str], output=None, realtime_priority: int = 0):
        self._nodes = nodes
        self._ros_args = ros_args
        self._realtime_priority = realtime_priority  # 0: every node at the default policy
        self._output = output or sys.stdout  # where the nodes' prefixed lines go
        self._events: queue.SimpleQueue = queue.SimpleQueue()
        self._processes: dict[str, subprocess.Popen] = {}
        self._pumps: list[threading.Thread] = []
        self._stop_requested = threading.Event()

    def on_signal(self, signum: int, _frame) -> None:
        self._stop_requested.set()
        self._events.put(("signal", signal.Signals(signum).name))

    def start(self) -> None:
        environment = {**os.environ, "PYTHONUNBUFFERED": "1"}
        for node in self._nodes:
            fifo_priority = self._realtime_priority if node.realtime else 0
            process = subprocess.Popen(
                node.command(self._ros_args, autostart=False),
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
                errors="replace",
                env=environment,
                start_new_session=True,  # a terminal's Ctrl-C reaches the nodes only through us
                preexec_fn=_child_setup(fifo_priority),
            )
            self._processes[node.name] = process
            say(f"started {node.name} (pid {process.pid}{f', SCHED_FIFO {fifo_priority}' if fifo_priority else ''})")
        # Threads only after every fork: preexec_fn is not safe while other threads run.
        for name, process in self._processes.items():
            pump = threading.Thread(target=self._pump, args=(name, process), daemon=True)
            pump.start()
            self._pumps.append(pump)

    def bring_up(self, stopping: Callable[[], bool] | None = None) -> str | None:
        """Configure every node, then activate them in data-flow order; why that failed, or
        None. A stop asked for meanwhile (a signal, or ``stopping()``) ends it early with None:
        the caller stops the graph as it would anyway."""
        stopping = stopping or self._stop_requested.is_set

        def give_up() -> str | None:
            if stopping():
                return "a stop was asked for"
            gone = self.exited()
            return f"{', '.join(gone)} exited by itself" if gone else None

        say("configuring every node, then activating them in data-flow order")
        try:
            bring_up([node.name for node in self._nodes], self._ros_args, give_up, say)
        except BringUpError as error:
            return None if stopping() else str(error)
        say("every node is active")
        return None

    def exited(self) -> list[str]:
        """Names of the nodes that have ended (for a caller that waits on something else)."""
        return [name for name, process in self._processes.items() if process.poll() is not None]

    def _pump(self, name: str, process: subprocess.Popen) -> None:
        first = True
        for line in process.stdout:
            self._output.write(f"[{name}] {line}")
            self._output.flush()
            if first:
                self._events.put(("up", name))
                first = False
        process.wait()
        self._events.put(("exit", name))

    def wait(self, duration_s: float | None) -> str | None:
        """Block until the graph should stop; return the name of a node that exited by
        itself, or None for a requested stop. ``duration_s`` counts from the moment every
        node has written its first line (a MOWS node's first line is its ``up`` message)."""
        up: set[str] = set()
        deadline = None
        while True:
            timeout = None if deadline is None else max(0.0, deadline - time.monotonic())
            try:
                kind, who = self._events.get(timeout=timeout)
            except queue.Empty:
                say(f"{duration_s} s have passed, stopping")
                return None
            if kind == "signal":
                say(f"{who} received, stopping")
                return None
            if kind == "exit":
                say(f"{who} exited by itself with code {self._processes[who].returncode}")
                return who
            up.add(who)
            if duration_s is not None and deadline is None and len(up) == len(self._nodes):
                deadline = time.monotonic() + duration_s

    def stop(self) -> dict[str, int]:
        """SIGINT every node still running, abort those that outlive STOP_TIMEOUT_S;
        return each node's exit code."""
        for process in self._processes.values():
            if process.poll() is None:
                process.send_signal(signal.SIGINT)
        deadline = time.monotonic() + STOP_TIMEOUT_S
        for name, process in self._processes.items():
            try:
                process.wait(timeout=max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                # SIGABRT first: the node's faulthandler (mows_ros.process) writes where each of
                # its threads is stuck into the log; SIGKILL only if even that does not end it.
                say(f"{name} did not stop within {STOP_TIMEOUT_S} s, aborting it (its stacks follow)")
                process.send_signal(signal.SIGABRT)
                try:
                    process.wait(timeout=ABORT_TIMEOUT_S)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.wait()
        for pump in self._pumps:
            pump.join()
        return {name: process.returncode for name, process in self._processes.items()}


def add_realtime_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--realtime-priority",
        type=realtime_priority,
        default=0,
        metavar="N",
        help="run the driver and the estimator under SCHED_FIFO at priority N (1-99; default: not)",
    )


def foxglove_port(text: str) -> int:
    """``--foxglove``'s port: a TCP port, 0 for any free one; argparse.ArgumentTypeError otherwise."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port number: {text!r}") from None
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"must be 0–65535 (0: any free port), got {port}")
    return port


def add_foxglove_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--foxglove",
        type=foxglove_port,
        nargs="?",
        const=FOXGLOVE_PORT,
        metavar="PORT",
        help=f"also serve the graph to Foxglove (the viz node) on PORT (default {FOXGLOVE_PORT}; 0: any free port)",
    )


def parse_arguments(argv: list[str]) -> tuple[argparse.Namespace, list[str]]:
    """Split ``argv`` into the runner's own options and the ROS arguments for every node."""
    own, ros_args = argv, []
    if "--ros-args" in argv:
        split = argv.index("--ros-args")
        own, ros_args = argv[:split], argv[split + 1 :]
    parser = argparse.ArgumentParser(
        prog="mows-graph", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--duration",
        type=float,
        metavar="S",
        help="stop after S seconds of every node running (default: run until SIGINT/SIGTERM)",
    )
    parser.add_argument(
        "--unconfigured",
        action="store_true",
        help="leave the nodes unconfigured, for a supervisor to bring up (lifecycle services)",
    )
    add_realtime_option(parser)
    add_foxglove_option(parser)
    args = parser.parse_args(own)
    if args.duration is not None and args.duration <= 0:
        parser.error(f"--duration must be positive, got {args.duration}")
    return args, ros_args


def main(argv: list[str] | None = None) -> int:
    args, ros_args = parse_arguments(sys.argv[1:] if argv is None else argv)
    if (problem := ros_arguments_problem(ros_args) or stage_problem(ros_args)) is not None:
        sys.stderr.write(f"mows-graph: error: {problem}\n")
        return EXIT_BAD_PARAMETER
    foxglove = args.foxglove is not None
    node_args = [*ros_args, *foxglove_arguments(args.foxglove)] if foxglove else ros_args
    graph = Graph(graph_nodes(foxglove), node_args, realtime_priority=args.realtime_priority)
    signal.signal(signal.SIGINT, graph.on_signal)
    signal.signal(signal.SIGTERM, graph.on_signal)
    graph.start()
    problem = None
    if args.unconfigured:
        say("nodes left unconfigured: configure and activate them through their lifecycle services")
    else:
        problem = graph.bring_up()
    if problem is not None:
        say(f"bring-up failed: {problem}")
    elif manual := manual_turns(ros_args):
        say(f"the {' and the '.join(manual)} turn the probe by hand: press Enter here once it is turned as asked")
        answer_turns_from(sys.stdin, ros_args)
    died = graph.wait(args.duration) if problem is None else None
    codes = graph.stop()
    unclean = {name: code for name, code in codes.items() if code != 0}
    if unclean:
        say("not stopped cleanly: " + ", ".join(f"{n} (code {c})" for n, c in unclean.items()))
    return 1 if problem is not None or died is not None or unclean else 0


if __name__ == "__main__":
    sys.exit(main())
