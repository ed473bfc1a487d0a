"""A cycle whose acceptance the caller never hears. Over a lossy link DDS drops a service's
response whose reader it has not matched yet, while the driver, which did receive the goal, runs
the cycle. The caller (the mapper, the calibrator) must still get that cycle's answer, asked for
by the goal's id, or its sweep loses every ring-down of the cycle; a goal the driver never
received is reported as unanswered at once, not awaited until the cycle's timeout.

Fits are volatile too: a cycle sent before discovery has matched the caller to a publisher of
the fits (an estimator) would have fits the caller never hears, so the caller waits for that
match before it sends the goal."""

import pytest
import rclpy
from mows_msgs.action import MeasurementCycle
from mows_msgs.msg import RingdownFit
from rclpy.action import ActionServer
from rclpy.task import Future

from mows.device.cycle.phases import CycleRequest
from mows_ros import cycles
from mows_ros.qos import RESULT_QOS

pytestmark = pytest.mark.ros

CYCLE_TIMEOUT_S = 60.0


@pytest.fixture
def stand_in(ros):
    """A driver's stand-in node that answers every cycle as cycle 7 with 3 ring-downs; the
    orientations it was asked for."""
    driver = rclpy.create_node("driver_stand_in")
    ros.executor.add_node(driver)
    executed = []

    def execute(goal_handle):
        executed.append(goal_handle.request.theta0_rad)
        goal_handle.succeed()
        return MeasurementCycle.Result(success=True, cycle_id=7, ringdowns_recorded=3)

    server = ActionServer(driver, MeasurementCycle, cycles.CYCLE_ACTION, execute)
    yield driver, executed
    server.destroy()
    ros.executor.remove_node(driver)
    driver.destroy_node()


@pytest.mark.parametrize("lost", ["the answer", "the goal"])
def test_a_cycle_whose_acceptance_is_lost_is_awaited_by_its_goal_id(ros, stand_in, monkeypatch, lost):
    monkeypatch.setattr(cycles, "GOAL_ANSWER_S", 1.0)
    driver, executed = stand_in
    driver.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)  # an estimator's
    client = cycles.DriverCycles(ros.node, lambda fit: None)
    send = client._client.send_goal_async

    def losing(goal, feedback_callback=None, goal_uuid=None):
        if lost == "the answer":  # the goal arrives, its acceptance does not
            send(goal, feedback_callback, goal_uuid)
        return Future()  # never answered

    monkeypatch.setattr(client._client, "send_goal_async", losing)
    ros.wait_for(client.ready, "the stand-in driver's action")
    task = ros.executor.create_task(client.run(CycleRequest(0.5, repeats=3), CYCLE_TIMEOUT_S))
    answer = ros.wait_for(lambda: task.done() and task.result(), "the cycle's answer", bound_s=20.0)
    if lost == "the answer":
        assert executed == [0.5]
        assert (answer.cycle_id, answer.ringdowns_recorded, answer.problem) == (7, 3, "")
    else:
        assert executed == []
        assert answer.problem == "the driver did not answer the cycle goal within 1 s"


def test_a_cycle_waits_until_a_publisher_of_its_fits_is_matched(ros, stand_in, monkeypatch):
    monkeypatch.setattr(cycles, "FITS_HEARD_S", 60.0)
    driver, executed = stand_in
    client = cycles.DriverCycles(ros.node, lambda fit: None)
    ros.wait_for(client.ready, "the stand-in driver's action")
    task = ros.executor.create_task(client.run(CycleRequest(0.25, repeats=1), CYCLE_TIMEOUT_S))
    for _ in range(20):  # 2 s of spinning: no estimator, no goal
        ros.executor.spin_once(timeout_sec=0.1)
    assert executed == [] and not task.done()
    driver.create_publisher(RingdownFit, "mows/ringdown", RESULT_QOS)
    answer = ros.wait_for(lambda: task.done() and task.result(), "the cycle's answer", bound_s=20.0)
    assert executed == [0.25]
    assert (answer.cycle_id, answer.problem) == (7, "")
