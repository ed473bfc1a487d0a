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
import importlib
import os
import queue
import resource
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import yaml
from ament_index_python.packages import get_package_prefix, get_package_share_directory

from mows_bringup.confirm import TURNING_NODES, confirm_turn
from mows_bringup.lifecycle import BringUpError, bring_up
from mows_ros.params import (
    ROS_OWN,
    nearest_hint,
    prefixed_overrides,
    renamed_to,
    ros_argument_values,
    unknown_name_hint,
)
from mows_ros.process import EXIT_BAD_PARAMETER, arguments_problem

STOP_TIMEOUT_S = 10.0  # a node still running this long after SIGINT is aborted
ABORT_TIMEOUT_S = 5.0  # and killed if it outlives the abort
PR_SET_PDEATHSIG = 1  # linux/prctl.h
_prctl = ctypes.CDLL(None, use_errno=True).prctl


@dataclass(frozen=True)
class GraphNode:
    """A node of the graph: its ROS name, package and console script."""

    name: str
    package: str
    executable: str
    realtime: bool = False  # on the ring-down path: --realtime-priority applies to it

    def config_path(self) -> str:
        share = Path(get_package_share_directory(self.package))
        return str(share / "config" / f"{self.name}.yaml")

    def command(self, ros_args: list[str], autostart: bool = True) -> list[str]:
        """The node alone, active once it has configured itself (``--autostart``); with
        ``autostart=False`` unconfigured, for a supervisor to bring up."""
        # Where ros2 run and launch_ros look for an ament_python console script.
        script = Path(get_package_prefix(self.package)) / "lib" / self.package / self.executable
        own = ["--autostart"] if autostart else []
        return [str(script), *own, "--ros-args", "--params-file", self.config_path(), *ros_args]


NODES = (  # in data-flow order: the order of activation
    GraphNode("driver", "mows_driver", "mows_driver", realtime=True),
    GraphNode("estimator", "mows_estimator", "mows_estimator", realtime=True),
    GraphNode("mapper", "mows_mapper", "mows_mapper"),
    GraphNode("calibrator", "mows_calibrator", "mows_calibrator"),
)
VIZ = GraphNode("viz", "mows_viz", "mows_viz")  # with --foxglove, after the others
FOXGLOVE_PORT = 8765  # Foxglove's default for a WebSocket connection


def foxglove_arguments(port: int) -> list[str]:
    """The viz node's ROS arguments for ``--foxglove=port``: the port and the shipped mount."""
    mount = Path(get_package_share_directory("mows_bringup")) / "urdf" / "mows_probe_mount.urdf"
    return ["-p", f"{VIZ.name}:port:={port}", "-p", f"{VIZ.name}:mount_file:={mount}"]


def graph_nodes(foxglove: bool) -> tuple[GraphNode, ...]:
    return (*NODES, VIZ) if foxglove else NODES


def parameter_rule_problem(rule: str) -> str | None:
    """Why ``-p rule``, given to every node, is refused: without a node's prefix every node but
    one would stop on it, a prefix or a name no node has reaches none. None when it is fine."""
    target = rule.partition(":=")[0]
    prefix, colon, name = target.rpartition(":")
    names = [node.name for node in (*NODES, VIZ)]
    if "/" in prefix:
        return None  # a fully qualified node name: rcl matches it, the node checks the name
    if name in ROS_OWN and (not colon or prefix in names):
        return None  # every node has it (use_sim_time): for all of them, or for the one named
    tables = {node.name: importlib.import_module(f"{node.package}.parameters").PARAMETERS for node in (*NODES, VIZ)}
    if not colon:
        return unprefixed_rule_problem(rule, name, tables)
    if prefix not in names:
        return f"-p {rule}: no node is called {prefix!r}: {nearest_hint(prefix, names, 'the nodes')}"
    if not any(spec.name == name for spec in tables[prefix]):
        return f"-p {rule}: the {prefix} has no parameter {name!r}: {unknown_name_hint(name, tables[prefix])}"
    return None


def unprefixed_rule_problem(rule: str, name: str, tables: dict) -> str:
    """Why ``-p rule`` without a node's prefix is refused: the rules to give instead (the new
    names of a renamed parameter), or the nearest name of any node's."""
    value = rule.partition(":=")[2]
    owners = [f"{n}:{name}" for n, table in tables.items() if any(spec.name == name for spec in table)]
    if owners:
        forms = " or ".join(f"-p {owner}:={value}" for owner in owners)
        return f"-p {rule} names no node, and every node would get it: give it as {forms}"
    renamed = [f"{n}:{spec.name}" for n, table in tables.items() if (spec := renamed_to(name, table)) is not None]
    if renamed:
        return f"-p {rule}: {name} was renamed: give it as " + " or ".join(f"-p {r}:={value}" for r in renamed)
    everyone = sorted({spec.name for table in tables.values() for spec in table})
    return f"-p {rule}: no node has a parameter {name!r}: {nearest_hint(name, everyone, 'see mows-graph --help')}"


def ros_arguments_problem(ros_args: list[str]) -> str | None:
    """Why the ROS arguments for every node are refused, or None (``parameter_rule_problem``)."""
    argv = ["mows-graph", "--ros-args", *ros_args]
    if (problem := arguments_problem(argv)) is not None:
        return problem
    rules = ros_argument_values(argv, ("-p", "--param"))
    return next((problem for rule in rules if (problem := parameter_rule_problem(rule)) is not None), None)


# Backends that cannot turn the stage: every orientation is the operator's turn, so the nodes
# whose goals turn the probe must ask for it (orientation manual), or each "angle" would be
# measured at the one angle the probe happens to stand at.
STAGELESS_BACKENDS = ("nidaqmx",)


def start_value(node: str, name: str, ros_args: list[str]):
    """The value ``node`` starts with for parameter ``name``: its parameter file's, then any
    ``--params-file``'s, then ``-p NODE:name:=value`` (the order rcl applies them in)."""
    argv = ["mows-graph", "--ros-args", *ros_args]
    graph_node = next(n for n in NODES if n.name == node)
    value = None
    for path in [graph_node.config_path(), *ros_argument_values(argv, ("--params-file",))]:
        for key, section in (yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}).items():
            if key.rsplit("/", 1)[-1] in (node, "**") and isinstance(section, dict):
                value = (section.get("ros__parameters") or {}).get(name, value)
    override = prefixed_overrides(node, argv, [n.name for n in NODES]).get(name)
    return override.value if override is not None else value


def stage_problem(ros_args: list[str]) -> str | None:
    """Why the graph is refused: a driver backend that cannot turn the stage with a node that
    would turn it (orientation stage); None when every turn is the operator's or the driver's."""
    backend = start_value("driver", "backend", ros_args)
    if backend not in STAGELESS_BACKENDS:
        return None
    turning = [node for node in TURNING_NODES if node not in manual_turns(ros_args)]
    if not turning:
        return None
    give = " ".join(f"-p {node}:orientation:=manual" for node in turning)
    return (
        f"driver backend {backend!r} cannot turn the stage, but the {' and the '.join(turning)} would "
        f"(orientation stage): every orientation would be measured where the probe stands. Give {give}: "
        "each turn is then asked for here and confirmed"
    )


def manual_turns(ros_args: list[str]) -> list[str]:
    """The nodes that will ask the operator to turn the probe by hand (``orientation: manual``)."""
    return [node for node in TURNING_NODES if start_value(node, "orientation", ros_args) == "manual"]


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
