"""The rule that cancels a cycle nobody waits for, on a stand-in graph.

Requirement: a cycle is cancelled once every client that was in the graph when it began has
left; never while one of them stays; and, if no client was ever seen, only after ``UNSEEN_S``
(the graph may show a client's request writer a moment after its request arrived).
"""

from types import SimpleNamespace

import pytest

from mows_ros import requesters
from mows_ros.requesters import UNSEEN_S, RequesterWatch

pytestmark = pytest.mark.ros

SERVICE = "/driver/run_cycle"


class Graph:
    """The request writers the graph shows, by DDS topic."""

    def __init__(self):
        self.writers: dict[str, list[bytes]] = {}

    def get_publishers_info_by_topic(self, topic: str, no_mangle: bool = False):
        assert no_mangle, "a service's request topic is a DDS name"
        return [SimpleNamespace(endpoint_gid=list(gid)) for gid in self.writers.get(topic, [])]

    def show(self, *gids: bytes) -> None:
        self.writers["rq/driver/run_cycleRequest"] = list(gids)


@pytest.fixture
def clock(monkeypatch):
    now = SimpleNamespace(s=100.0)
    monkeypatch.setattr(requesters.time, "monotonic", lambda: now.s)
    return now


def test_a_cycle_runs_while_one_of_its_requesters_stays(clock):
    graph = Graph()
    graph.show(b"mapper", b"cli")
    watch = RequesterWatch(graph, (SERVICE,))
    graph.show(b"mapper", b"another")  # the command-line client left, another came
    clock.s += 60
    assert not watch.gone()
    graph.show(b"another")  # a client that came later never asked for this cycle
    assert watch.gone()


def test_a_requester_seen_a_moment_after_its_request_is_watched(clock):
    graph = Graph()
    watch = RequesterWatch(graph, (SERVICE,))
    clock.s += UNSEEN_S / 2
    assert not watch.gone()  # not yet shown: too early to tell
    graph.show(b"cli")
    clock.s += UNSEEN_S
    assert not watch.gone()
    graph.show()
    assert watch.gone()


def test_a_requester_never_seen_is_taken_as_gone_after_the_graph_had_time(clock):
    graph = Graph()
    watch = RequesterWatch(graph, (SERVICE,))
    clock.s += UNSEEN_S * 0.99
    assert not watch.gone()
    clock.s += UNSEEN_S * 0.02
    assert watch.gone()
