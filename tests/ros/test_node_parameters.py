"""The nodes' parameter tables: declared with descriptors, validated on set, and the same
as the shipped parameter files."""

import dataclasses
import hashlib
import shutil
import subprocess

import pytest
import yaml
from rclpy.parameter import Parameter

from mows.estimate.probe_set import own_probe_entry
from mows.physics.probe import PAPER_PROBE
from mows.sim.scenario import DEFAULT_SCENARIO, load_scenario, scenario_file
from mows_bringup.nodes import NODES, VIZ
from mows_calibrator import node as calibrator
from mows_driver import node as driver
from mows_estimator import node as estimator
from mows_mapper import node as mapper
from mows_mapper.parameters import sweep_settings
from mows_ros.node import GRAPH_NODE_NAMES
from mows_ros.process import EXIT_BAD_PARAMETER

pytestmark = pytest.mark.ros

NODE_MODULES = {"driver": driver, "estimator": estimator, "mapper": mapper, "calibrator": calibrator}
NODE_CLASSES = {
    "driver": driver.DriverNode,
    "estimator": estimator.EstimatorNode,
    "mapper": mapper.MapperNode,
    "calibrator": calibrator.CalibratorNode,
}


@pytest.mark.parametrize("graph_node", NODES, ids=lambda n: n.name)
def test_the_parameter_file_holds_every_parameter_at_its_default(graph_node):
    with open(graph_node.config_path()) as file:
        ((key, section),) = yaml.safe_load(file).items()
    assert key == f"/**/{graph_node.name}"
    table = NODE_MODULES[graph_node.name].PARAMETERS
    assert section["ros__parameters"] == {spec.name: spec.default for spec in table}


@pytest.mark.parametrize(
    "node_name, name, value",
    [
        ("driver", "backend", "usb"),
        ("driver", "block_duration_s", 0.051),
        ("driver", "block_duration_s", 0.009),
        ("driver", "coil_current_cap_a", 20.0),  # read-only
        ("driver", "block_duration_s", float("nan")),
        ("mapper", "repeats_per_angle", 0),
        ("estimator", "buffer_s", 10.0),  # read-only
        ("estimator", "probe_file", "/nonexistent/probe.yaml"),
        ("mapper", "probe_file", "/nonexistent/probe.yaml"),
        ("mapper", "reference_scenario", "no_such_scenario"),
        ("driver", "supply_current_cap_a", 5.0),  # read-only
        ("calibrator", "scenario", "paper_largest_spacing"),  # no supply section
        ("calibrator", "gradient_scenario", "no_such_scenario"),
        ("calibrator", "nominal_probe_file", "/nonexistent/probe.yaml"),
    ],
)
def test_bad_values_are_rejected(ros_context, node_name, name, value):
    node = NODE_CLASSES[node_name]()
    before = node.get_parameter(name).value
    (result,) = node.set_parameters([Parameter(name, value=value)])
    assert not result.successful
    assert name in result.reason
    assert node.get_parameter(name).value == before
    node.destroy_node()


def test_good_values_are_taken_and_described(ros_context):
    node = driver.DriverNode()
    (result,) = node.set_parameters([Parameter("block_duration_s", value=0.05)])
    assert result.successful, result.reason
    assert node.get_parameter("block_duration_s").value == 0.05
    (limits,) = node.describe_parameter("block_duration_s").floating_point_range
    assert (limits.from_value, limits.to_value) == (0.01, 0.05)
    assert node.describe_parameter("coil_current_cap_a").read_only
    assert "sim" in node.describe_parameter("backend").additional_constraints
    node.destroy_node()


def test_a_probe_file_is_read_when_set_and_refused_with_its_reason(ros_context, tmp_path):
    node = estimator.EstimatorNode()
    path = tmp_path / "probe.yaml"
    dataclasses.replace(PAPER_PROBE, damping_per_s=2.5).to_yaml(path)
    (result,) = node.set_parameters([Parameter("probe_file", value=str(path))])
    assert result.successful, result.reason
    assert [p.probe.damping_per_s for p in node._settings().probes] == [2.5]
    path.write_text("moment_am2: -1\n")
    (result,) = node.set_parameters([Parameter("probe_file", value=str(path))])
    assert not result.successful and "probe_file" in result.reason and "lacks" in result.reason
    assert [p.probe.damping_per_s for p in node._settings().probes] == [2.5]  # the accepted file's probe stays in use
    node.destroy_node()


def test_the_mappers_settings_hold_its_own_probe_as_a_set_of_one_unless_probes_names_them():
    values = {spec.name: spec.default for spec in mapper.PARAMETERS}
    own = sweep_settings(values, PAPER_PROBE)
    assert own.probes == (own_probe_entry(PAPER_PROBE),) and not own.named
    named = sweep_settings(values | {"probes": "{0: 112.5, 2: 125.0}"}, PAPER_PROBE)
    assert [e.probe_id for e in named.probes] == [0, 2] and named.named


def test_a_bad_value_at_start_up_stops_the_node():
    run = subprocess.run(NODES[0].command(["-p", "backend:=usb"]), capture_output=True, text=True, timeout=120)
    assert run.returncode == EXIT_BAD_PARAMETER, run.stderr
    assert "backend='usb' is not one of sim, serial, bag, nidaqmx" in run.stderr
    assert "Traceback" not in run.stderr


# A misspelling of one parameter of each node, and the name it should suggest.
MISSPELT = {
    "driver": ("excitation_curent_a", "excitation_current_a"),
    "estimator": ("coil_off_skip", "coil_off_skip_s"),
    "mapper": ("referance_scenario", "reference_scenario"),
    "calibrator": ("hardware_idd", "hardware_id"),
}


@pytest.mark.parametrize("graph_node", NODES, ids=lambda n: n.name)
@pytest.mark.parametrize("given_by", ["-p", "parameter file"])
def test_an_unknown_parameter_stops_the_node_with_the_nearest_name(graph_node, given_by, tmp_path):
    wrong, right = MISSPELT[graph_node.name]
    assert right in {spec.name for spec in NODE_MODULES[graph_node.name].PARAMETERS}
    if given_by == "-p":
        arguments = ["-p", f"{wrong}:=1.0"]
    else:
        path = tmp_path / "params.yaml"
        path.write_text(yaml.safe_dump({f"/**/{graph_node.name}": {"ros__parameters": {wrong: 1.0}}}))
        arguments = ["--params-file", str(path)]
    run = subprocess.run(graph_node.command(arguments), capture_output=True, text=True, timeout=120)
    assert run.returncode == EXIT_BAD_PARAMETER, run.stderr
    assert f"unknown parameter '{wrong}'" in run.stderr and f"did you mean {right}?" in run.stderr
    assert "Traceback" not in run.stderr


def test_a_parameter_for_another_node_is_not_refused():
    """`-p driver:repeats:=3` (rcl's node-name prefix, as mows-graph passes it to every node)
    reaches the driver only; the estimator starts with it on its command line."""
    run = subprocess.run(
        NODES[1].command(["-p", "driver:repeats:=3", "-p", "estimator:coil_off_skip:=1.0"]),
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert run.returncode == EXIT_BAD_PARAMETER and "did you mean coil_off_skip_s?" in run.stderr
    assert "repeats" not in run.stderr


def one_line_refusal(run: subprocess.CompletedProcess) -> str:
    """The one line a refused command wrote (its ROS log lines aside; a blank line counts): exit
    status 2, no traceback."""
    assert run.returncode == EXIT_BAD_PARAMETER, run.stderr
    assert "Traceback" not in run.stderr
    (line,) = [line for line in run.stderr.splitlines() if not line.startswith("[")]
    return line


NOT_ROS_PARAMETERS = "probe settings\n"  # YAML, but no node: rcl applies nothing from it


@pytest.mark.parametrize(
    "graph_node, arguments, reason",
    [
        (NODES[0], ["--params-file", "/nonexistent/params.yaml"], "Couldn't parse params file"),
        (NODES[0], ["--params-file", "{malformed}"], "Couldn't parse params file"),
        (NODES[0], ["--params-file", "{not_ros}"], "not a ROS parameter file"),
        (NODES[0], ["-p", "repeats"], "the form is -p [node:]name:=value"),
        (NODES[0], ["-p", "serial_port:="], "rule: '-p serial_port:=' (the form is -p [node:]name:=value"),
        (NODES[3], ["-p", "currents_a:=[]"], "'currents_a' is not initialized: currents_a: give it a value"),
        (NODES[0], ["-p", "drvier:repeats:=3"], "no node is called 'drvier': did you mean driver?"),
        # the node-prefixed form inside a namespace, which rcl alone would drop
        (NODES[1], ["-r", "__ns:=/probe_a", "-p", "estimator:coil_off_skip:=1.0"], "did you mean coil_off_skip_s?"),
    ],
    ids=["missing-file", "malformed-file", "not-parameters", "no-value", "empty-value", "empty-list", "prefix", "ns"],
)
def test_node_arguments_it_cannot_take_end_it_in_one_line(graph_node, arguments, reason, tmp_path):
    files = {"{malformed}": "driver: [\n", "{not_ros}": NOT_ROS_PARAMETERS}
    for placeholder, text in files.items():
        (tmp_path / placeholder).write_text(text)
    arguments = [str(tmp_path / a) if a in files else a for a in arguments]
    run = subprocess.run(graph_node.command(arguments), capture_output=True, text=True, timeout=120)
    line = one_line_refusal(run)
    assert line.startswith("error: ") and reason in line, line


@pytest.mark.parametrize(
    "command, reason",
    [
        (["mows-graph", "--ros-args", "-p", "repeats:=5"], "give it as -p driver:repeats:=5"),
        (["mows-graph", "--ros-args", "-p", "driver:scenaro:=helmholtz"], "did you mean scenario?"),
        (
            ["mows-graph", "--ros-args", "-p", "settle_s:=0.2"],
            "settle_s was renamed: give it as -p driver:turn_settle_s:=0.2 or -p estimator:coil_off_skip_s:=0.2",
        ),
        (["mows-graph", "--ros-args", "-p", "calibrator:probe_file:=p.yaml"], "renamed probe_output_file"),
        (["mows-demo", "--scenario", "nosuch"], "--scenario nosuch: scenario 'nosuch' is neither"),
        (
            ["mows-graph", "--ros-args", "-p", "driver:backend:=nidaqmx"],
            "driver backend 'nidaqmx' cannot turn the stage, but the mapper and the calibrator would (orientation "
            "stage): every orientation would be measured where the probe stands. Give -p mapper:orientation:=manual "
            "-p calibrator:orientation:=manual",
        ),
        (
            ["mows-graph", "--ros-args", "-p", "driver:backend:=nidaqmx", "-p", "mapper:orientation:=manual"],
            "cannot turn the stage, but the calibrator would (orientation stage)",
        ),
    ],
    ids=[
        "graph-unprefixed",
        "graph-misspelt",
        "graph-renamed",
        "graph-renamed-prefixed",
        "demo-scenario",
        "graph-stage-on-nidaqmx",
        "graph-calibrator-stage-on-nidaqmx",
    ],
)
def test_the_graph_s_commands_refuse_bad_arguments_in_one_line_before_starting_a_node(command, reason):
    line = one_line_refusal(subprocess.run(command, capture_output=True, text=True, timeout=120))
    assert reason in line, line


@pytest.mark.parametrize(
    "option, scenario, name",
    [("--scenario", "anti_helmholtz", "demo_scene.yaml"), ("--probe-scenario", "calibration", "calibrated_probe.yaml")],
    ids=["scene", "probe-scene"],
)
def test_the_demo_refuses_an_out_that_holds_a_scenario_it_reads(tmp_path, option, scenario, name):
    """A scenario the demo reads, where it would write its own file of that name: refused before
    any work, in one line, the scenario byte for byte as it was and nothing else written."""
    given = tmp_path / name
    shutil.copy(scenario_file(scenario), given)
    digest = hashlib.sha256(given.read_bytes()).hexdigest()
    command = ["mows-demo", option, str(given), "--out", str(tmp_path)]
    line = one_line_refusal(subprocess.run(command, capture_output=True, text=True, timeout=120))
    assert f"output {given} is an input" in line, line
    assert hashlib.sha256(given.read_bytes()).hexdigest() == digest
    assert list(tmp_path.iterdir()) == [given]


def test_the_graph_s_node_names_are_the_ones_every_node_knows():
    """A node takes ``-p NAME:…`` for another node of the graph silently, and refuses any other
    prefix: the names it knows must be the graph's."""
    assert tuple(node.name for node in (*NODES, VIZ)) == GRAPH_NODE_NAMES


# Parameters that meant two things, by their previous release's name: each is refused wherever it
# is set, with the new name, and nothing is taken under the old one.
RENAMED = [
    ("driver", "settle_s", "turn_settle_s", 0.2, "-p"),
    ("estimator", "settle_s", "coil_off_skip_s", 0.002, "parameter file"),
    ("calibrator", "probe_file", "probe_output_file", "p.yaml", "-p"),
]


@pytest.mark.parametrize("node_name, old, new, value, given_by", RENAMED, ids=[r[0] for r in RENAMED])
def test_a_renamed_parameter_is_refused_wherever_it_is_set_with_its_new_name(
    ros_context, node_name, old, new, value, given_by, tmp_path
):
    node = NODE_CLASSES[node_name]()
    before = node.get_parameter(new).value
    result = node.set_parameters_atomically([Parameter(old, value=value)])  # as ros2 param set's service does
    assert not result.successful and f"unknown parameter '{old}': renamed {new}" in result.reason, result.reason
    assert result.reason.endswith(f"set {new}") and node.get_parameter(new).value == before
    assert not node.has_parameter(old)
    node.destroy_node()
    if given_by == "-p":
        arguments = ["-p", f"{old}:={value}"]
    else:
        path = tmp_path / "params.yaml"
        path.write_text(yaml.safe_dump({f"/**/{node_name}": {"ros__parameters": {old: value}}}))
        arguments = ["--params-file", str(path)]
    graph_node = next(n for n in NODES if n.name == node_name)
    line = one_line_refusal(subprocess.run(graph_node.command(arguments), capture_output=True, text=True, timeout=120))
    assert f"unknown parameter '{old}': renamed {new}" in line and f"set {new}" in line, line


def test_the_graph_takes_a_stage_the_nodes_can_turn_or_the_operator_turns(tmp_path):
    from mows_bringup.nodes import stage_problem

    manual = ["-p", "mapper:orientation:=manual", "-p", "calibrator:orientation:=manual"]
    assert stage_problem(["-p", "driver:backend:=nidaqmx", *manual]) is None
    assert stage_problem([]) is None  # the sim backend turns its simulated stage
    params = tmp_path / "bench.yaml"  # the same from a parameter file as from -p
    params.write_text("/**/driver:\n  ros__parameters:\n    backend: nidaqmx\n")
    assert "the mapper and the calibrator would" in stage_problem(["--params-file", str(params)])
    assert stage_problem(["--params-file", str(params), *manual]) is None


def test_the_driver_reads_its_scenario_once_and_checks_tracking_against_it(ros_context, monkeypatch):
    """Parameter changes are checked against the scenario read once: set four times, tracking's
    plan is made from it each time, and the scenario file is read once."""
    from mows.device.backends import factory

    reads = []
    monkeypatch.setattr(factory, "load_scenario", lambda name: reads.append(name) or load_scenario(name))
    node = driver.DriverNode()
    for target_t in (1e-6, 0.5e-6, 0.3e-6):
        result = node.set_parameters_atomically(
            [Parameter("tracking", value=True), Parameter("tracking_target_std_t", value=target_t)]
        )
        assert result.successful, result.reason
    (refused,) = node.set_parameters([Parameter("tracking_target_std_t", value=1e-9)])
    assert not refused.successful and "below the Cramér–Rao bound" in refused.reason
    assert reads == [DEFAULT_SCENARIO]
    node.destroy_node()


def test_tracking_is_planned_from_the_scenario_as_read_not_as_the_file_is_now(tmp_path):
    from mows_driver import parameters

    scene = tmp_path / "scene.yaml"
    load_scenario("anti_helmholtz").to_yaml(scene)
    values = {spec.name: spec.default for spec in parameters.PARAMETERS} | {"scenario": str(scene), "tracking": True}
    settings = parameters.backend_settings(values)
    scene.unlink()  # nothing reads it again
    assert parameters.settings_problem(values, settings) is None
    tracking = parameters.tracking_settings(values, settings)
    assert tracking.excitation_current_a == values["coil_current_cap_a"] and tracking.ringdown_s > 0
