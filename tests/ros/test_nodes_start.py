"""The node graph as processes: mows-graph starts the three nodes, each reports on
/diagnostics, takes ROS arguments (use_sim_time for all nodes or one), and the graph stops
cleanly (exit 0) after --duration or on a signal; a node that dies makes it fail. A node alone
takes a `/**/node` parameter file in a namespace and stops cleanly on SIGTERM."""

import os
import pathlib
import re
import signal
import subprocess
import sys

import pytest
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.srv import GetParameters

from mows_bringup.graph import parse_arguments
from mows_bringup.load import Load
from mows_bringup.nodes import NODES
from node_processes import START_S, log

pytestmark = pytest.mark.ros

NODE_NAMES = {f"/{node.name}" for node in NODES}


@pytest.fixture
def diagnostics(ros):
    """The last status heard on /diagnostics, by status name."""
    heard = {}
    ros.node.create_subscription(
        DiagnosticArray, "/diagnostics", lambda a: heard.update((s.name, s) for s in a.status), 10
    )
    return heard


def hear_all(ros, heard: dict, names: set[str], process: subprocess.Popen) -> None:
    ros.wait_for(lambda: names <= heard.keys() or process.poll() is not None, f"diagnostics of {names}", START_S)
    assert names <= heard.keys(), f"heard only {sorted(heard)}\n{log(process)}"
    assert all(heard[name].level == DiagnosticStatus.OK for name in names)


def exit_code(ros, process: subprocess.Popen) -> int:
    ros.wait_for(lambda: process.poll() is not None, "the process to exit")
    return process.returncode


def test_graph_runs_for_its_duration_and_stops_cleanly(ros, diagnostics, start):
    graph = start("mows-graph", "--duration", "5")
    hear_all(ros, diagnostics, NODE_NAMES, graph)
    assert exit_code(ros, graph) == 0, log(graph)


STARTS = 5  # each about 10 s at a load of 10


@pytest.mark.slow
def test_the_graph_starts_under_load_and_answers_every_first_call(ros, start):
    """Beside two CPU burners and a 1 kHz JointState loop, the graph is started STARTS times
    and each node's parameters are asked for as soon as it serves them (a ``ros2 param get``):
    every answer comes, and no node says it dropped one ("failed to send response (timeout)":
    its client's reader not yet discovered, mows_ros.answers)."""
    load = Load()
    load.start()
    try:
        for _ in range(STARTS):
            # Stopped once every node answered: with --duration, counted from the nodes' first
            # lines, it could stop before this node has discovered their services.
            graph = start("mows-graph")
            for node in NODES:
                use_sim_time(ros, f"/{node.name}")
            graph.send_signal(signal.SIGINT)
            assert exit_code(ros, graph) == 0, log(graph)
            assert "failed to send response" not in log(graph), log(graph)
    finally:
        load.stop()


def use_sim_time(ros, node_name: str) -> bool:
    client = ros.node.create_client(GetParameters, f"{node_name}/get_parameters")
    try:
        ros.wait_for(client.service_is_ready, f"{node_name}'s parameters", START_S)
        answer = client.call_async(GetParameters.Request(names=["use_sim_time"]))
        return ros.wait_for(lambda: answer.done() and answer.result(), "the answer").values[0].bool_value
    finally:
        ros.node.destroy_client(client)


def test_graph_passes_ros_arguments_and_forwards_sigterm(ros, diagnostics, start):
    # use_sim_time, ROS's own parameter, for every node and (prefixed) for one of them.
    sim_time = ["-p", "use_sim_time:=true", "-p", "mapper:use_sim_time:=false"]
    graph = start("mows-graph", "--realtime-priority", "10", "--ros-args", "-r", "__ns:=/lab", *sim_time)
    hear_all(ros, diagnostics, {f"/lab{name}" for name in NODE_NAMES}, graph)
    assert {node.name: use_sim_time(ros, f"/lab/{node.name}") for node in NODES} == {
        node.name: node.name != "mapper" for node in NODES
    }
    # The ring-down path runs under SCHED_FIFO at the asked priority, the rest as before.
    for node in NODES:
        pid = int(re.search(rf"started {node.name} \(pid (\d+)", log(graph)).group(1))
        policy, priority = os.sched_getscheduler(pid), os.sched_getparam(pid).sched_priority
        assert (policy, priority) == ((os.SCHED_FIFO, 10) if node.realtime else (os.SCHED_OTHER, 0)), node
    assert {node.name for node in NODES if node.realtime} == {"driver", "estimator"}
    graph.send_signal(signal.SIGTERM)
    assert exit_code(ros, graph) == 0, log(graph)
    assert "SIGTERM received" in log(graph)


def test_graph_fails_when_a_node_dies(ros, diagnostics, start):
    graph = start("mows-graph")
    hear_all(ros, diagnostics, NODE_NAMES, graph)
    pid = int(re.search(r"started driver \(pid (\d+)\)", log(graph)).group(1))
    os.kill(pid, signal.SIGKILL)
    assert exit_code(ros, graph) == 1, log(graph)
    assert "driver exited by itself" in log(graph)


def test_a_node_in_a_namespace_takes_its_parameter_file_and_stops_on_sigterm(ros, diagnostics, start, tmp_path):
    overrides = tmp_path / "driver.yaml"
    overrides.write_text(yaml.safe_dump({"/**/driver": {"ros__parameters": {"block_duration_s": 0.04}}}))
    driver = start(*NODES[0].command(["-r", "__ns:=/lab", "--params-file", str(overrides)]))
    hear_all(ros, diagnostics, {"/lab/driver"}, driver)
    values = {kv.key: kv.value for kv in diagnostics["/lab/driver"].values}
    assert values["block_duration_s"] == "0.04"
    driver.send_signal(signal.SIGTERM)
    assert exit_code(ros, driver) == 0, log(driver)
    # It releases the device while its context still runs: its last lines reach /rosout too,
    # and none fails to ("publisher's context is invalid").
    assert "device closed" in log(driver) and "Failed to publish log message" not in log(driver), log(driver)


@pytest.mark.parametrize("priority", ["0.5", "100", "-1"])
def test_a_realtime_priority_out_of_range_is_refused_in_one_line(priority, capsys):
    with pytest.raises(SystemExit) as stopped:
        parse_arguments(["--realtime-priority", priority])
    assert stopped.value.code == 2
    assert "--realtime-priority" in capsys.readouterr().err


def test_graph_arguments_split_at_ros_args():
    args, ros_args = parse_arguments(["--duration", "3", "--ros-args", "-r", "__ns:=/x"])
    assert (args.duration, ros_args) == (3.0, ["-r", "__ns:=/x"])
    with pytest.raises(SystemExit):
        parse_arguments(["--duration", "0"])


# A node process whose executor fails on a take as another thread shuts the context
# down from under it (the binding's RuntimeError), that thread still ``late_s`` from done; or
# never (None): a failure that is no shutdown.
TAKE_FAILS = """
import sys, threading, rclpy
from rclpy.executors import SingleThreadedExecutor
from mows_ros import process
late_s = {late_s}
def spin_once(self, timeout_sec=None):
    if late_s is not None:
        threading.Timer(late_s, rclpy.try_shutdown).start()
    raise RuntimeError("Unable to convert call argument '0' to Python object")
SingleThreadedExecutor.spin_once = spin_once
process.SHUTDOWN_WAIT_S = 1.0
sys.exit(process.run_node(lambda: rclpy.create_node("take_fails"), ["take_fails"]))
"""


@pytest.mark.parametrize("late_s", [0.3, None])
def test_a_take_that_fails_as_the_context_shuts_down_is_a_clean_stop_and_only_then(late_s):
    run = subprocess.run([sys.executable, "-c", TAKE_FAILS.format(late_s=late_s)], capture_output=True, text=True)
    if late_s is None:
        assert run.returncode == 1 and "RuntimeError: Unable to convert" in run.stderr, run.stderr
    else:
        assert run.returncode == 0, run.stderr


def shm_segments(pid: int | str) -> set[str]:
    """The Fast DDS shared-memory segments (not the ports) process ``pid`` has mapped."""
    try:
        maps = pathlib.Path(f"/proc/{pid}/maps").read_text()
    except OSError:  # a process that ended meanwhile
        return set()
    return set(re.findall(r"/dev/shm/(fastrtps_[0-9a-f]{16})(?:\s|$)", maps))


def test_a_stopped_node_leaves_the_graph_and_none_of_its_shared_memory(ros, diagnostics, start):
    """The calibrator (action servers, a lifecycle state machine: handles that outlive
    destroy_node in reference cycles) stopped on SIGINT unlinks its own segments: each it mapped
    but this process had not mapped before it started (the others are this process's own)."""
    ours = shm_segments(os.getpid())
    calibrator = start(*next(node for node in NODES if node.name == "calibrator").command([]))
    hear_all(ros, diagnostics, {"/calibrator"}, calibrator)
    its_own = shm_segments(calibrator.pid) - ours
    assert its_own, "the node maps no segment of its own: nothing to check"
    calibrator.send_signal(signal.SIGINT)
    assert exit_code(ros, calibrator) == 0, log(calibrator)
    assert not {name for name in its_own if (pathlib.Path("/dev/shm") / name).exists()}
