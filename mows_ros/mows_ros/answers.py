"""Service answers that reach a client the node has only half discovered.

A ROS service is two DDS topics: the request reaches the node as soon as it has discovered the
client's request writer, but the answer can be sent only once its response writer has matched
the client's response reader, which discovery may announce later. Fast DDS (rmw_fastrtps) waits
100 ms for that match, then drops the answer, and rclpy says so with a RuntimeWarning, "failed
to send response (timeout): client will not receive response". On a loaded computer the
reader can come later than that: the node prints that line and the client waits in vain (seen
in 4 of 17 starts of the graph, on a client's first calls).

:func:`answering_when_heard` makes a service send such an answer again, every ``RETRY_S`` from
a timer, until the client's reader is matched, for at most ``ANSWER_WAIT_S``; every other
warning raised meanwhile is passed on. The executor is held by one try at a time, never for
the whole wait: the node's other callbacks (its stream, its diagnostics, other answers) run
between the tries. An answer still not sent then is logged once with the service's name.
"""

import time
import warnings
from collections.abc import Callable

from rclpy.exceptions import InvalidHandle
from rclpy.service import Service

# How long an answer is tried again: discovery under a load of 15 on 2 cores takes up to a
# second or two.
ANSWER_WAIT_S = 3.0
RETRY_S = 0.05  # between two tries (each try waits up to 100 ms itself, in rmw_fastrtps)
LOST = "failed to send response (timeout)"  # rclpy's RuntimeWarning for an answer dropped

# ``every(period_s, callback)`` calls ``callback`` every ``period_s`` (on the node's executor,
# on a steady clock) until the function it returned is called.
Every = Callable[[float, Callable[[], None]], Callable[[], None]]


def answering_when_heard(service: Service, warn: Callable[[str], object], every: Every) -> Service:
    """``service`` with its ``send_response`` (what the executor calls with each answer) tried
    again from ``every``'s timer while the client's reader is not yet matched; ``warn`` logs
    an answer given up. A service that answers so already is left as it is."""
    send = service.send_response
    if getattr(send, "when_heard", False):
        return service

    def send_response(response, header) -> None:
        if not _sent(send, response, header):
            _Retry(service.srv_name, lambda: _sent(send, response, header), warn, every)

    send_response.when_heard = True  # type: ignore[attr-defined]
    service.send_response = send_response
    return service


class _Retry:
    """One answer tried again every ``RETRY_S`` until ``send()`` sends it or ``ANSWER_WAIT_S``
    has passed."""

    def __init__(self, name: str, send: Callable[[], bool], warn: Callable[[str], object], every: Every):
        self.name, self.send, self.warn = name, send, warn
        self.deadline = time.monotonic() + ANSWER_WAIT_S
        self.done = False
        self.stop = every(RETRY_S, self.again)

    def again(self) -> None:
        if self.done:  # a tick already queued when the answer went out
            return
        try:
            sent = self.send()
        except InvalidHandle:  # the service is gone (the node is stopping): nobody to answer
            self.done = True
            self.stop()
            return
        if sent or time.monotonic() > self.deadline:
            self.done = True
            self.stop()
            if not sent:
                self.warn(f"an answer of {self.name} was lost: its client was not discovered in {ANSWER_WAIT_S:g} s")


def _sent(send, response, header) -> bool:
    """Whether ``send`` sent the answer (no "failed to send response (timeout)" warning)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        send(response, header)
    lost = False
    for warning in caught:
        if issubclass(warning.category, RuntimeWarning) and str(warning.message).startswith(LOST):
            lost = True
        else:  # another thread's, raised meanwhile: not ours to keep
            warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
    return not lost
