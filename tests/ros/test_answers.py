"""An answer to a client the node has only half discovered is sent again until it goes out.

The stand-in service drops an answer as rclpy 7.1 over rmw_fastrtps does while the client's
response reader is not matched: ``send_response`` returns after a RuntimeWarning "failed to
send response (timeout): client will not receive response" (rclpy's PyErr_WarnFormat), and the
answer is gone. It is matched only after a given number of tries."""

import types
import warnings

import pytest

from mows_ros import answers
from mows_ros.answers import ANSWER_WAIT_S, answering_when_heard

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


def test_an_answer_is_sent_again_until_the_client_is_matched():
    service, logged = HalfDiscovered(matched_at=4), []
    answering_when_heard(service, logged.append)
    with warnings.catch_warnings(record=True) as printed:
        warnings.simplefilter("always")
        service.send_response("active", "header 1")
    assert service.delivered == [("active", "header 1")] and service.tries == 4
    assert not printed and not logged  # no line on the node's output: the answer went out


def test_other_warnings_raised_meanwhile_are_passed_on():
    service = HalfDiscovered(matched_at=1)
    send = service.send_response

    def send_with_a_worker_warning(response, header):
        warnings.warn("invalid value encountered in divide", RuntimeWarning, stacklevel=1)
        send(response, header)

    service.send_response = send_with_a_worker_warning
    answering_when_heard(service, [].append)
    with warnings.catch_warnings(record=True) as printed:
        warnings.simplefilter("always")
        service.send_response("active", "header 1")
    assert [str(w.message) for w in printed] == ["invalid value encountered in divide"]
    assert service.delivered == [("active", "header 1")]


def test_a_client_never_matched_is_given_up_after_the_bound_with_one_line(monkeypatch):
    now = types.SimpleNamespace(s=0.0)

    def monotonic():
        now.s += 0.1  # each try waits 100 ms in rmw_fastrtps
        return now.s

    monkeypatch.setattr(answers.time, "monotonic", monotonic)
    service, logged = HalfDiscovered(matched_at=10**6), []
    answering_when_heard(service, logged.append)
    with warnings.catch_warnings(record=True) as printed:
        warnings.simplefilter("always")
        service.send_response("active", "header 1")
    assert not service.delivered and not printed
    assert 0.9 * ANSWER_WAIT_S / 0.1 <= service.tries <= ANSWER_WAIT_S / 0.1 + 2
    assert logged == [f"an answer of /driver/get_state was lost: its client was not discovered in {ANSWER_WAIT_S:g} s"]


def test_a_service_made_to_answer_so_twice_is_wrapped_once():
    """rclpy makes the parameter services through create_service, which a node wraps, during the
    node's own construction, before it wraps every service it has."""
    service = HalfDiscovered(matched_at=2)
    once = answering_when_heard(service, [].append).send_response
    assert answering_when_heard(service, [].append).send_response is once
