"""An answer to a client the node has only half discovered is sent again until it goes out,
from a timer: the executor is held by one try at a time, never for the whole wait.

The stand-in service drops an answer as rclpy 7.1 over rmw_fastrtps does while the client's
response reader is not matched: ``send_response`` returns after a RuntimeWarning "failed to
send response (timeout): client will not receive response" (rclpy's PyErr_WarnFormat), and the
answer is gone. It is matched only after a given number of tries. The stand-in timers are
ticked by the test, as an executor would between its other callbacks."""

import types
import warnings

import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter

from mows_ros import answers
from mows_ros.answers import ANSWER_WAIT_S, RETRY_S, answering_when_heard
from mows_ros.node import MowsNode

pytestmark = pytest.mark.ros

DROPPED = "failed to send response (timeout): client will not receive response, at ./src/rmw_response.cpp:154"


class HalfDiscovered:
    """A service whose client's reader is matched from the ``matched_at``-th answer on."""

    srv_name = "/driver/get_state"

    def __init__(self, matched_at: int):
        self.matched_at, self.tries, self.delivered = matched_at, 0, []

    def send_response(self, response, header) -> None:
        self.tries += 1
        if self.tries < self.matched_at:
            warnings.warn(DROPPED, RuntimeWarning, stacklevel=1)
            return
        self.delivered.append((response, header))


class Timers:
    """Stand-in timers: ``every`` as a node gives it; ``tick`` runs each running timer once."""

    def __init__(self):
        self.running: dict[int, tuple[float, object]] = {}
        self.started = 0

    def every(self, period_s, callback):
        key = self.started = self.started + 1
        self.running[key] = (period_s, callback)
        return lambda: self.running.pop(key)  # a second stop would raise: stopped once

    def tick(self) -> None:
        for _, callback in list(self.running.values()):
            callback()


def test_an_answer_is_sent_again_from_a_timer_until_the_client_is_matched():
    service, logged, timers = HalfDiscovered(matched_at=4), [], Timers()
    answering_when_heard(service, logged.append, timers.every)
    with warnings.catch_warnings(record=True) as printed:
        warnings.simplefilter("always")
        service.send_response("active", "header 1")
        # The executor has its thread back after one try; the next come from a timer.
        assert service.tries == 1 and not service.delivered
        assert [period for period, _ in timers.running.values()] == [RETRY_S]
        while timers.running:
            timers.tick()
    assert service.delivered == [("active", "header 1")] and service.tries == 4
    assert not printed and not logged  # no line on the node's output: the answer went out


def test_an_answer_sent_at_once_starts_no_timer():
    service, timers = HalfDiscovered(matched_at=1), Timers()
    answering_when_heard(service, [].append, timers.every)
    service.send_response("active", "header 1")
    assert service.delivered == [("active", "header 1")] and timers.started == 0


def test_answers_to_two_half_discovered_clients_are_each_sent_once():
    service, timers = HalfDiscovered(matched_at=5), Timers()
    answering_when_heard(service, [].append, timers.every)
    service.send_response("active", "header 1")
    service.send_response("inactive", "header 2")
    while timers.running:
        timers.tick()
    assert sorted(service.delivered) == [("active", "header 1"), ("inactive", "header 2")]


def test_other_warnings_raised_meanwhile_are_passed_on():
    service = HalfDiscovered(matched_at=1)
    send = service.send_response

    def send_with_a_worker_warning(response, header):
        warnings.warn("invalid value encountered in divide", RuntimeWarning, stacklevel=1)
        send(response, header)

    service.send_response = send_with_a_worker_warning
    answering_when_heard(service, [].append, Timers().every)
    with warnings.catch_warnings(record=True) as printed:
        warnings.simplefilter("always")
        service.send_response("active", "header 1")
    assert [str(w.message) for w in printed] == ["invalid value encountered in divide"]
    assert service.delivered == [("active", "header 1")]


def test_a_client_never_matched_is_given_up_after_the_bound_with_one_line(monkeypatch):
    now = types.SimpleNamespace(s=0.0)
    monkeypatch.setattr(answers.time, "monotonic", lambda: now.s)
    service, logged, timers = HalfDiscovered(matched_at=10**6), [], Timers()
    answering_when_heard(service, logged.append, timers.every)
    with warnings.catch_warnings(record=True) as printed:
        warnings.simplefilter("always")
        service.send_response("active", "header 1")
        while timers.running:
            now.s += RETRY_S + 0.1  # each try waits 100 ms in rmw_fastrtps
            timers.tick()
    assert not service.delivered and not printed
    tries = round(ANSWER_WAIT_S / (RETRY_S + 0.1))  # within the bound, as many as fit in it
    assert tries <= service.tries <= tries + 2
    assert logged == [f"an answer of /driver/get_state was lost: its client was not discovered in {ANSWER_WAIT_S:g} s"]


def test_a_service_made_to_answer_so_twice_is_wrapped_once():
    """rclpy makes the parameter services through create_service, which a node wraps, during the
    node's own construction, before it wraps every service it has."""
    service = HalfDiscovered(matched_at=2)
    once = answering_when_heard(service, [].append, Timers().every).send_response
    assert answering_when_heard(service, [].append, Timers().every).send_response is once


def test_a_node_tries_again_on_the_steady_clock_under_sim_time_with_no_clock_published(ros_context):
    """A node's own timers (``MowsNode.every``): use_sim_time with no /clock stops the ROS
    clock, never the tries."""
    node = MowsNode("answering", ())
    node.set_parameters([Parameter("use_sim_time", value=True)])
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        service, logged, timers = HalfDiscovered(matched_at=3), [], set(node.timers)
        answering_when_heard(service, logged.append, node.every)
        service.send_response("active", "header 1")
        for _ in range(100):
            if service.delivered:
                break
            executor.spin_once(timeout_sec=RETRY_S)
        assert service.delivered == [("active", "header 1")] and not logged
        assert set(node.timers) == timers  # the retry's timer is gone with the answer
    finally:
        executor.remove_node(node)
        node.destroy_node()
        executor.shutdown()
