"""Who may still be waiting for a request that runs on (the driver's cycle, the mapper's sweep, the
calibrator's run), read from the ROS graph: the request writers of the clients of the interface
it was asked through. The rule is the core's (:class:`mows.sweep.requests.Requesters`, with
``UNSEEN_S``); this module only reads the graph and the steady clock for it.

``ros2 service call`` and ``ros2 action send_goal`` each make a client of their own. A client
that leaves cleanly (it exits, or is stopped with SIGINT or SIGTERM) is gone from the graph at
once; one killed outright is gone when DDS's liveliness lease of its process expires. An
interface served under two names (a node's own and the previous release's alias) is watched
under both: the server is not told which one a request came through.
"""

import time
from collections.abc import Sequence

from rclpy.node import Node

from mows.sweep.requests import UNSEEN_S as UNSEEN_S
from mows.sweep.requests import Requesters


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


def steady_s() -> float:
    """Now on the steady clock the requesters' rule is fed (seconds)."""
    return time.monotonic()


class RequesterWatch:
    """The clients that may wait for one request, asked through one of ``service_names`` (an
    action's: its ``/_action/send_goal``), looked up in ``node``'s graph now and at each :meth:`gone`."""

    def __init__(self, node: Node, service_names: Sequence[str]):
        self._node, self.service_names = node, tuple(service_names)
        self._requesters = Requesters(self.service_names, request_writers(node, self.service_names), steady_s())

    @property
    def reason(self) -> str:
        """Why the request is cancelled once :meth:`gone`."""
        return self._requesters.reason

    def gone(self) -> bool:
        """Whether every client that may wait for the request has left the graph."""
        return self._requesters.gone(request_writers(self._node, self.service_names), steady_s())
