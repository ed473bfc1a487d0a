"""Every mows_msgs message, service and action through rclpy in one process, with a
non-default value in every field, compared field by field on arrival."""

import pytest
from action_msgs.msg import GoalStatus
from rclpy.action import ActionClient, ActionServer

from message_equality import assert_same
from rclpy_conversion import rclpy_class, to_rclpy
from samples import ACTIONS, MESSAGES, SERVICES, sample_message

pytestmark = pytest.mark.ros


def sample(msgtype: str):
    return to_rclpy(sample_message(msgtype), rclpy_class(msgtype))


@pytest.mark.parametrize("name", MESSAGES)
def test_message_is_published_and_received(ros, name):
    msgtype = f"mows_msgs/msg/{name}"
    sent = sample(msgtype)
    received = []
    ros.node.create_subscription(type(sent), "roundtrip", received.append, 10)
    publisher = ros.node.create_publisher(type(sent), "roundtrip", 10)
    ros.wait_for(publisher.get_subscription_count, "the subscription to match")
    publisher.publish(sent)
    ros.wait_for(lambda: received, f"the {name} message")
    assert_same(received[0], sent)


@pytest.mark.parametrize("name", SERVICES)
def test_service_is_called_and_answered(ros, name):
    msgtype = f"mows_msgs/srv/{name}"
    request, response = sample(f"{msgtype}_Request"), sample(f"{msgtype}_Response")
    requests = []

    def answer(got, _empty_response):
        requests.append(got)
        return response

    ros.node.create_service(rclpy_class(msgtype), "roundtrip", answer)
    client = ros.node.create_client(rclpy_class(msgtype), "roundtrip")
    ros.wait_for(client.service_is_ready, f"the {name} service")
    future = client.call_async(request)
    ros.wait_for(future.done, f"the {name} response")
    assert_same(requests[0], request)
    assert_same(future.result(), response)


@pytest.mark.parametrize("name", ACTIONS)
def test_action_goal_feedback_and_result(ros, name):
    msgtype = f"mows_msgs/action/{name}"
    goal, feedback, result = (sample(f"{msgtype}_{part}") for part in ("Goal", "Feedback", "Result"))
    goals = []

    def execute(handle):
        goals.append(handle.request)
        handle.publish_feedback(feedback)
        handle.succeed()
        return result

    ActionServer(ros.node, rclpy_class(msgtype), "roundtrip", execute)
    client = ActionClient(ros.node, rclpy_class(msgtype), "roundtrip")
    ros.wait_for(client.server_is_ready, f"the {name} action server")
    feedbacks = []
    sent = client.send_goal_async(goal, feedback_callback=feedbacks.append)
    handle = ros.wait_for(lambda: sent.done() and sent.result(), "the goal response")
    assert handle.accepted
    outcome = handle.get_result_async()
    ros.wait_for(outcome.done, "the result")
    ros.wait_for(lambda: feedbacks, "the feedback")
    assert_same(goals[0], goal)
    assert_same(feedbacks[0].feedback, feedback)
    assert outcome.result().status == GoalStatus.STATUS_SUCCEEDED
    assert_same(outcome.result().result, result)
