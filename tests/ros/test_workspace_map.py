"""The workspace map through the graph: the mapper node asks a simulated CRTK arm for each pose
(geometry_msgs/PoseStamped on ``arm/move_cp``), takes the sweep's pose from the arm's
``arm/measured_cp``, and sweeps there through a stand-in driver whose ring-downs are the probe's
physics where the arm truly put it, in an eight-coil field from Biot–Savart. The map it
publishes (transient local) and its ``field_at`` service predict held-out points within 2σ.

The arm is harder than a real one where a map feels it: its reports are 20 ms late, every move
ends off its goal by a draw of its stated accuracy, and the probe sweeps where it truly is."""

import json
import math
import re
import shlex
from pathlib import Path

import numpy as np
import pytest
import yaml
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseStamped
from mows_msgs.action import RotationSweep, WorkspaceMap
from mows_msgs.msg import ExcitationState, RingdownFit, SweepDecomposition, WorkspaceModel
from mows_msgs.srv import FieldAt
from rcl_interfaces.srv import GetParameters
from rclpy.action import ActionClient

from mows.cli.main import main
from mows.device.cycle.phases import Phase
from mows.physics.probe import PAPER_PROBE
from mows.records import stamps
from mows.sim.navigation import navigation_system
from mows.workspace.arm import NS_PER_S, Reach, SimulatedArm, StampedPose
from mows.workspace.poses import PoseError
from mows.workspace.simulated import RINGDOWN_STD_HZ, SweepPose, ball_points, sweep_shifts_hz
from mows_driver.recording import open_recorder
from mows_mapper.parameters import PARAMETERS
from mows_ros.qos import EXCITATION_QOS, MAP_QOS, RESULT_QOS, maps_qos
from node_processes import goal_answer, log, send_goal, serve_cycles

pytestmark = pytest.mark.ros

CENTRE_M = np.array([0.3, 0.0, 0.0])  # the workspace in the arm's base frame
RADIUS_M = 0.015
SWEEPS = 10
ANGLES = np.radians(np.arange(0.0, 360.0, 45.0))
ACCURACY = PoseError(1e-4, math.radians(0.01))  # an industrial arm's, stated to the mapper
DOC = Path(__file__).parents[2] / "docs" / "workspace_maps.md"
MAP_BOUND_S = 400.0  # a bound for a hang only: 80 cycles and a fit, on a loaded machine


def now_s(ros) -> float:
    return ros.node.get_clock().now().nanoseconds / NS_PER_S


class ArmNode:
    """A SimulatedArm on CRTK topics: measured_cp at 50 Hz, goals on move_cp."""

    def __init__(self, ros, rng):
        self.ros = ros
        self.arm = SimulatedArm(
            rng, ACCURACY, PoseError(1e-6, 1e-6), Reach((0.0, 0.0, 0.0), 0.1, 0.6), 0.02, 1.0, 20.0, "arm_base"
        )
        self.refusals = []
        self.measured = ros.node.create_publisher(PoseStamped, "arm/measured_cp", 10)
        ros.node.create_subscription(PoseStamped, "arm/move_cp", self.on_goal, 10)
        ros.node.create_timer(0.02, self.publish)

    def on_goal(self, msg: PoseStamped) -> None:
        if not (answer := self.arm.move_cp(StampedPose.of(msg), now_s(self.ros))).accepted:
            self.refusals.append(answer.reason)

    def publish(self) -> None:
        pose = self.arm.measured_cp(now_s(self.ros))
        msg = PoseStamped()
        stamps.set_nanoseconds(msg.header.stamp, pose.stamp_ns)
        msg.header.frame_id = pose.frame_id
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = pose.position_m.tolist()
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = pose.orientation_xyzw.tolist()
        self.measured.publish(msg)


class ArmDriver:
    """Answers measurement cycles with ring-down fits of the probe where the arm truly holds it."""

    def __init__(self, ros, arm: SimulatedArm, rng, turned_by_arm: bool):
        self.ros, self.arm, self.rng, self.cycle = ros, arm, rng, 0
        self.turned_by_arm = turned_by_arm  # no stage: the probe sits at θ = 0 in the arm's tool frame
        self.source = navigation_system(1.5e-3, seed=2)  # about the workspace's centre
        self.fits = ros.node.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
        self.excitation = ros.node.create_publisher(ExcitationState, "mows/excitation", EXCITATION_QOS)
        self.server = serve_cycles(ros, self.run_cycle)

    def run_cycle(self, request, response):
        truth = self.arm.true_pose(now_s(self.ros))  # refuses a probe between poses
        pose = SweepPose(truth.position_m - CENTRE_M, truth.plane)
        self.cycle += 1
        theta0 = 0.0 if self.turned_by_arm else request.theta0_rad
        for repeat in range(request.repeats):
            ringdown = ExcitationState(
                phase=int(Phase.RINGDOWN), phase_name="RINGDOWN", cycle_id=self.cycle, repeat_index=repeat
            )
            ringdown.repeats, ringdown.theta0_rad = request.repeats, request.theta0_rad
            stamps.set_nanoseconds(ringdown.header.stamp, self.ros.node.get_clock().now().nanoseconds)
            self.excitation.publish(ringdown)
            shift = sweep_shifts_hz(self.source, pose, PAPER_PROBE, np.array([theta0]))[0]
            shift += RINGDOWN_STD_HZ * self.rng.standard_normal()
            msg = RingdownFit(
                cycle_id=self.cycle,
                repeat_index=repeat,
                status=RingdownFit.STATUS_OK,
                status_name="OK",
                theta0_rad=request.theta0_rad,
                frequency_hz=PAPER_PROBE.f00_hz + shift,
                frequency_std_hz=RINGDOWN_STD_HZ,
                frequency_shift_hz=shift,
                frequency_shift_std_hz=RINGDOWN_STD_HZ,
                amplitude_rad=math.radians(2.0),
                damping_per_s=1.8,
                duration_s=0.5,
            )
            stamps.set_nanoseconds(msg.header.stamp, self.ros.node.get_clock().now().nanoseconds)
            self.fits.publish(msg)
        response.success, response.cycle_id, response.ringdowns_recorded = True, self.cycle, request.repeats
        return response


# What the driver records of the graph (its ``record_path``): the cycles, the fits, the maps.
RECORDED = (
    ("/mows/excitation", ExcitationState, EXCITATION_QOS),
    ("/mows/ringdown", RingdownFit, RESULT_QOS),
    ("/mows/sweep", SweepDecomposition, maps_qos(16)),
    ("/mows/workspace_model", WorkspaceModel, MAP_QOS),
)


def record(ros, path):
    recorder = open_recorder(str(path), list(RECORDED))
    for topic, cls, qos in RECORDED:
        write = lambda msg, topic=topic: recorder.write(topic, msg, ros.node.get_clock().now().nanoseconds)  # noqa: E731
        ros.node.create_subscription(cls, topic, write, qos)
    return recorder


def start_mapper(action_server, turn_with: str):
    return action_server(
        "mapper",
        WorkspaceMap,
        "mapper/workspace_map",
        f"arm_position_std_m:={ACCURACY.position_std_m}",
        f"arm_angle_std_deg:={math.degrees(ACCURACY.angle_std_rad)}",
        f"turn_with:={turn_with}",
    )


def run_map(ros, client, **goal):
    _, done, feedback = send_goal(ros, client, WorkspaceMap.Goal(**goal), result_bound_s=MAP_BOUND_S)
    return done, feedback


def field_at(ros, point_m, moment_am2=(0.0, 0.0, 0.0)) -> FieldAt.Response:
    client = ros.node.create_client(FieldAt, "mapper/field_at")
    ros.wait_for(client.service_is_ready, "the field_at service")
    request = FieldAt.Request(tool_moment_am2=list(moment_am2))
    request.position.x, request.position.y, request.position.z = (float(v) for v in point_m)
    answer = client.call_async(request)
    return ros.wait_for(lambda: answer.done() and answer.result(), "field_at's answer")


@pytest.mark.slow
@pytest.mark.parametrize("turn_with", ["stage", "arm"])
def test_the_mapper_maps_the_workspace_at_poses_it_asks_the_arm_for(ros, action_server, turn_with, tmp_path, capsys):
    """With ``turn_with`` arm there is no stage: the arm's last joint turns the probe to each
    orientation (on move_cp, the tool frame turned about its z), and the driver's probe sits at
    θ = 0 in the tool frame."""
    client, _ = start_mapper(action_server, turn_with)
    rng = np.random.default_rng(4)
    arm = ArmNode(ros, rng)
    driver = ArmDriver(ros, arm.arm, np.random.default_rng(5), turn_with == "arm")
    recorder = record(ros, tmp_path / "session")
    done, feedback = run_map(
        ros,
        client,
        sweeps=SWEEPS,
        centre_m=CENTRE_M.tolist(),
        radius_m=RADIUS_M,
        theta0_rad=ANGLES.tolist(),
        repeats_per_angle=1,
    )
    assert done.status == GoalStatus.STATUS_SUCCEEDED and done.result.success, done.result.message
    swept = [f for f in feedback if f.accepted]
    assert len(swept) == SWEEPS and not arm.refusals, [f.refusal for f in feedback]
    # Each sweep's pose is the arm's report, on the workspace's sphere, each a different one.
    positions = np.array([[f.pose.pose.position.x, f.pose.pose.position.y, f.pose.pose.position.z] for f in swept])
    np.testing.assert_allclose(np.linalg.norm(positions - CENTRE_M, axis=1), RADIUS_M, atol=1e-5)
    assert np.min(np.linalg.norm(positions[:, None] - positions[None], axis=2) + np.eye(SWEEPS)) > 2e-3
    # The map is latched, and shows its coefficients with their σ.
    models = []
    ros.node.create_subscription(WorkspaceModel, "mows/workspace_model", models.append, MAP_QOS)
    model = ros.wait_for(lambda: models, "the latched workspace model")[0]
    assert model.header.frame_id == "arm_base" and len(model.poses) == SWEEPS
    assert len(model.coefficients_t) == len(model.coefficient_std_t) == (model.degree + 1) ** 2 - 1
    assert np.all(np.array(model.coefficient_std_t) > 0)
    # Held-out points: within 2σ (95 % of a normal; the points share one fit's few largest errors).
    points = ball_points(12, RADIUS_M, np.random.default_rng(9))
    field_pulls, gradient_pulls = [], []
    for point in points:
        answer = field_at(ros, CENTRE_M + point, (0.0, 0.0, 0.1))
        assert answer.success, answer.message
        field_pulls.append((np.array(answer.field_t) - driver.source.field_t(point)) / answer.field_std_t)
        gradient = driver.source.gradient_t_per_m(point).ravel()
        gradient_pulls.append((np.array(answer.gradient_t_per_m) - gradient) / answer.gradient_std_t_per_m)
    assert np.mean(np.abs(field_pulls) < 2) > 0.85, np.std(field_pulls)
    assert np.mean(np.abs(gradient_pulls) < 2) > 0.85, np.std(gradient_pulls)
    # The tool's torque m × B and force G·m follow from the same prediction.
    answer = field_at(ros, CENTRE_M, (0.0, 0.0, 0.1))
    np.testing.assert_allclose(answer.torque_nm, np.cross([0.0, 0.0, 0.1], answer.field_t), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(answer.force_n, np.reshape(answer.gradient_t_per_m, (3, 3)) @ [0.0, 0.0, 0.1], rtol=1e-9)
    # The docs' request (``ros2 service call``, which the wheels do not carry), through rclpy.
    printed = yaml.safe_load(
        re.search(r"ros2 service call /mapper/field_at mows_msgs/srv/FieldAt \\\n\s*\"(.*?)\"", DOC.read_text())[1]
    )
    position = printed["position"]
    answer = field_at(ros, [position["x"], position["y"], position["z"]], printed["tool_moment_am2"])
    assert answer.success, answer.message
    # The recording alone makes the same map again (`mows map BAG`): one path, live and offline.
    recorder.close()
    capsys.readouterr()
    assert main(["map", str(tmp_path / "session"), "--json"]) == 0
    again = json.loads(capsys.readouterr().out)["workspace"]
    assert again["degree"] == model.degree and again["sweeps"] == SWEEPS
    np.testing.assert_allclose(
        again["coefficients_t"], model.coefficients_t, rtol=0, atol=1e-6 * min(model.coefficient_std_t)
    )
    outside = field_at(ros, CENTRE_M + [0.0, 0.0, 2 * RADIUS_M])
    assert not outside.success and "outside its 15.0 mm" in outside.message
    # A workspace the arm cannot reach is refused with the reason, and the arm not moved.
    done, _ = run_map(ros, client, sweeps=3, centre_m=[0.9, 0.0, 0.0], radius_m=RADIUS_M)
    assert done.status == GoalStatus.STATUS_ABORTED and "no pose left within the arm's reach" in done.result.message


@pytest.mark.slow
def test_a_map_owns_the_mapper_until_its_cancel_ends_it_at_once(ros, action_server):
    """A client's sweep goal is refused while a map runs (between its sweeps too); the map's
    cancel ends it with no further sweep, and the log says it was cancelled, not that a pose
    was refused."""
    client, mapper = start_mapper(action_server, "stage")
    arm = ArmNode(ros, np.random.default_rng(4))
    ArmDriver(ros, arm.arm, np.random.default_rng(5), False)
    feedback = []
    goal = WorkspaceMap.Goal(
        sweeps=3, centre_m=CENTRE_M.tolist(), radius_m=RADIUS_M, theta0_rad=ANGLES.tolist(), repeats_per_angle=1
    )
    handle = goal_answer(ros, client, goal, feedback.append)
    assert handle.accepted
    ros.wait_for(lambda: feedback, "the map's first sweep", MAP_BOUND_S)
    sweeps = ActionClient(ros.node, RotationSweep, "mapper/rotation_sweep")
    ros.wait_for(sweeps.server_is_ready, "the rotation sweep action")
    _, refused, _ = send_goal(ros, sweeps, RotationSweep.Goal(theta0_rad=ANGLES.tolist(), repeats_per_angle=1))
    assert refused.status == GoalStatus.STATUS_ABORTED, refused.result.message
    assert refused.result.message == "sweep goal refused: a workspace map is running"
    handle.cancel_goal_async()
    result = handle.get_result_async()
    done = ros.wait_for(lambda: result.done() and result.result(), "the cancelled map's end", MAP_BOUND_S)
    assert done.status == GoalStatus.STATUS_CANCELED and done.result.message == "workspace map cancelled"
    assert len([f for f in feedback if f.accepted]) < 3
    assert "workspace map cancelled" in log(mapper) and "pose refused" not in log(mapper), log(mapper)


def printed_graph_command() -> str:
    """`mows-graph --ros-args -p mapper:NAME:=VALUE ...` as docs/workspace_maps.md prints it."""
    return re.search(r"    (mows-graph --ros-args .*?)\n\n", DOC.read_text(), re.S)[1]


def test_the_docs_command_that_connects_an_arm_sets_the_mappers_parameters():
    """Every NAME of the printed command is a mapper parameter and every VALUE within its limits."""
    given = dict(re.findall(r"-p mapper:(\w+):=(\S+)", printed_graph_command()))
    table = {spec.name: spec for spec in PARAMETERS}
    assert given and set(given) <= set(table), set(given) - set(table)
    for name, text in given.items():
        value = type(table[name].default)(text)
        assert table[name].request_problem(value, name) is None


@pytest.mark.slow
@pytest.mark.xdist_group("realtime")
def test_the_docs_command_that_connects_an_arm_runs_as_printed(ros, start):
    """The printed command, run as printed, brings the graph up with its mapper on the named
    arm's CRTK topics and with the printed accuracy."""
    command = printed_graph_command()
    graph = start(*shlex.split(command.replace("\\\n", " ")))
    given = dict(re.findall(r"-p mapper:(\w+):=(\S+)", command))
    arm = given["arm"]
    ros.wait_for(
        lambda: ros.node.count_subscribers(f"/{arm}/measured_cp") and ros.node.count_publishers(f"/{arm}/move_cp"),
        "the mapper on the arm's measured_cp and move_cp",
        MAP_BOUND_S,
    )
    ros.wait_for(lambda: "every node is active" in log(graph), "the bring-up", MAP_BOUND_S)
    client = ros.node.create_client(GetParameters, "/mapper/get_parameters")
    ros.wait_for(client.service_is_ready, "the mapper's parameters")
    answer = client.call_async(GetParameters.Request(names=list(given)))
    values = ros.wait_for(lambda: answer.done() and answer.result(), "the mapper's parameters").values
    read = {name: value.string_value or value.double_value for name, value in zip(given, values)}
    assert read == {name: text if name in ("arm", "arm_frame") else float(text) for name, text in given.items()}
