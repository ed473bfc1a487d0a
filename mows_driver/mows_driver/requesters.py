"""Who may still be waiting for a cycle: the nodes that held a client of the interface it was
asked through, looked up in the ROS graph.

A service or action server is not told who sent a request. So a cycle remembers the nodes that
held a client of its service or action when it began (``ros2 service call`` and
``ros2 action send_goal`` each make a node of their own); once none of them holds one any more,
nobody can take its answer, and the driver cancels it. A node that leaves the graph cleanly
(it exits, or is stopped with SIGINT or SIGTERM) is gone at once; one killed outright is gone
when DDS's liveliness lease of its process expires. While another of those nodes stays (a
mapper beside a command-line client), the cycle runs on: the rule never cancels a cycle whose
requester may still be there.
"""

from rclpy.node import Node, NodeNameNonExistentError

Requester = tuple[str, str]  # (node name, namespace)


def holds_client(node: Node, requester: Requester, service_name: str) -> bool:
    """Whether the node ``requester`` is in the graph with a client of ``service_name``."""
    try:
        services = node.get_client_names_and_types_by_node(*requester)
    except NodeNameNonExistentError:  # it has left
        return False
    return any(service == service_name for service, _ in services)


def client_holders(node: Node, service_name: str) -> frozenset[Requester]:
    """The nodes of the graph (``node`` excepted) that hold a client of ``service_name``."""
    own = (node.get_name(), node.get_namespace())
    return frozenset(
        requester
        for requester in node.get_node_names_and_namespaces()
        if requester != own and holds_client(node, requester, service_name)
    )


class RequesterWatch:
    """The nodes that may wait for one cycle, asked through ``service_name`` (an action's:
    its ``/_action/send_goal``)."""

    def __init__(self, node: Node, service_name: str):
        self._node, self.service_name = node, service_name
        self.requesters = client_holders(node, service_name)

    def gone(self) -> bool:
        """Whether every node that may wait for the cycle has left (False while none was seen:
        the graph may not yet know the client whose request came)."""
        if not self.requesters:
            self.requesters = client_holders(self._node, self.service_name)
            return False
        return not any(holds_client(self._node, r, self.service_name) for r in self.requesters)
