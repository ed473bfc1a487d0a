"""Service answers that reach a client the node has only half discovered.

A ROS service is two DDS topics: the request reaches the node as soon as it has discovered the
client's request writer, but the answer can be sent only once its response writer has matched
the client's response reader, which discovery may announce later. Fast DDS (rmw_fastrtps) waits
100 ms for that match, then drops the answer, and rclpy says so with a RuntimeWarning, "failed
to send response (timeout): client will not receive response". On a loaded computer the
reader can come later than that: the node prints that line and the client waits in vain (seen
in 4 of 17 starts of the graph, on a client's first calls).

:func:`answering_when_heard` makes a service send such an answer again until the client's reader
is matched, for at most ``ANSWER_WAIT_S``; every other warning raised meanwhile is passed on.
An answer still not sent then is logged once with the service's name.
"""

import time
import warnings

from rclpy.service import Service

# How long an answer is tried again: discovery under a load of 15 on 2 cores takes up to a
# second or two; each try waits up to 100 ms itself (rmw_fastrtps), so the executor is held at
# most this long, and only while a client is half discovered.
ANSWER_WAIT_S = 3.0
LOST = "failed to send response (timeout)"  # rclpy's RuntimeWarning for an answer dropped


def answering_when_heard(service: Service, warn) -> Service:
    """``service`` with its ``send_response`` (what the executor calls with each answer) tried
    again while the client's reader is not yet matched; ``warn`` logs an answer given up.
    A service that answers so already is left as it is."""
    send = service.send_response
    if getattr(send, "when_heard", False):
        return service

    def send_response(response, header) -> None:
        deadline = time.monotonic() + ANSWER_WAIT_S
        while not _sent(send, response, header):
            if time.monotonic() > deadline:
                warn(f"an answer of {service.srv_name} was lost: its client was not discovered in {ANSWER_WAIT_S:g} s")
                return

    send_response.when_heard = True  # type: ignore[attr-defined]
    service.send_response = send_response
    return service


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
