"""Who may still be waiting for a cycle: the clients of the interface it was asked through,
looked up in the ROS graph by their request writers.

A service or action server is not told who sent a request. So a cycle remembers the request
writers (DDS endpoints, by GID) of the clients of its service or action when it began
(``ros2 service call`` and ``ros2 action send_goal`` each make a client of their own); once none
of them is in the graph any more, nobody can take its answer, and the driver cancels it. The
graph knows a writer as soon as DDS has matched it, which a request needs to arrive at all; the
node that holds it is learnt later, so a requester stopped at once may leave before its node is
ever known, but never before its writer is. A client that leaves cleanly (it exits, or is
stopped with SIGINT or SIGTERM) is gone at once; one killed outright is gone when DDS's
liveliness lease of its process expires. While another of those clients stays (a mapper beside a
command-line client), the cycle runs on: the rule never cancels a cycle whose requester may still
be there. Should no client of the interface be seen at all for ``UNSEEN_S`` after the request,
the requester left before the graph could show it, and the cycle is cancelled.
"""

import time

from rclpy.node import Node

UNSEEN_S = 2.0  # far beyond the graph's lag behind DDS matching (milliseconds)


def request_writers(node: Node, service_name: str) -> frozenset[bytes]:
    """The GIDs of the request writers of every client of ``service_name`` in the graph."""
    # The DDS topic of a service's requests, as every Jazzy RMW names it.
    topic = f"rq{service_name}Request"
    return frozenset(bytes(info.endpoint_gid) for info in node.get_publishers_info_by_topic(topic, no_mangle=True))


class RequesterWatch:
    """The clients that may wait for one cycle, asked through ``service_name`` (an action's:
    its ``/_action/send_goal``)."""

    def __init__(self, node: Node, service_name: str):
        self._node, self.service_name = node, service_name
        self._asked_s = time.monotonic()
        self.requesters = request_writers(node, service_name)

    def gone(self) -> bool:
        """Whether every client that may wait for the cycle has left the graph."""
        present = request_writers(self._node, self.service_name)
        if not self.requesters:
            self.requesters = present
            return not present and time.monotonic() - self._asked_s > UNSEEN_S
        return not self.requesters & present
