"""Who may still be waiting for a request that runs on (the driver's cycle, the mapper's sweep, the
calibrator's run): the clients of the interface it was asked through, looked up in the ROS
graph by their request writers.

A service or action server is not told who sent a request. So a request remembers the request
writers (DDS endpoints, by GID) of the clients of its service or action when it began
(``ros2 service call`` and ``ros2 action send_goal`` each make a client of their own); once none
of them is in the graph any more, nobody can take its answer, and the node cancels it. The
graph knows a writer as soon as DDS has matched it, which a request needs to arrive at all; the
node that holds it is learnt later, so a requester stopped at once may leave before its node is
ever known, but never before its writer is. A client that leaves cleanly (it exits, or is
stopped with SIGINT or SIGTERM) is gone at once; one killed outright is gone when DDS's
liveliness lease of its process expires. While another of those clients stays (a mapper beside a
command-line client), the request runs on: the rule never cancels one whose requester may still
be there. Should no client of the interface be seen at all for ``UNSEEN_S`` after the request,
the requester left before the graph could show it, and the request is cancelled. An interface
served under two names (a node's own and the previous release's alias) is watched under both:
the server is not told which one a request came through.
"""

import time
from collections.abc import Sequence

from rclpy.node import Node

UNSEEN_S = 2.0  # far beyond the graph's lag behind DDS matching (milliseconds)


def request_writers(node: Node, service_names: Sequence[str]) -> frozenset[bytes]:
    """The GIDs of the request writers of every client of each of ``service_names`` in the graph."""
    # The DDS topic of a service's requests, as every Jazzy RMW names it.
    return frozenset(
        bytes(info.endpoint_gid)
        for name in service_names
        for info in node.get_publishers_info_by_topic(f"rq{name}Request", no_mangle=True)
    )


def send_goal_services(node: Node, action_names: Sequence[str]) -> tuple[str, ...]:
    """The services an action's goals are asked through, for each of its names (resolved in ``node``)."""
    return tuple(node.resolve_service_name(name) + "/_action/send_goal" for name in action_names)


class RequesterWatch:
    """The clients that may wait for one request, asked through one of ``service_names`` (an
    action's: its ``/_action/send_goal``); ``service_name`` is the first, for the log."""

    def __init__(self, node: Node, service_names: Sequence[str]):
        self._node, self.service_names = node, tuple(service_names)
        self.service_name = self.service_names[0]
        self._asked_s = time.monotonic()
        self.requesters = request_writers(node, self.service_names)

    def gone(self) -> bool:
        """Whether every client that may wait for the request has left the graph."""
        present = request_writers(self._node, self.service_names)
        if not self.requesters:
            self.requesters = present
            return not present and time.monotonic() - self._asked_s > UNSEEN_S
        return not self.requesters & present
