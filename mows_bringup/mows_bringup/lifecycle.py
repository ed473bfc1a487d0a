"""Managed nodes brought up through their ``lifecycle_msgs`` services, as a supervisor does:
``configure`` every node at once (each loads its files and compiles in its own process), then
``activate`` them one by one in data-flow order, each once the one before it is active.

The client has a ROS context of its own, so that a program with its own (mows-demo) is not
disturbed, and takes the graph's ROS arguments: a namespace given to the nodes
(``-r __ns:=/probe_a``) applies to the names it calls (``driver/change_state``).
"""

import math
import time
from collections.abc import Callable, Sequence

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from rclpy.task import Future

from mows_bringup.own_node import OwnNode

# A bound for a hang only; each wait ends as soon as its answer comes. A node's start-up and its
# configure (which compiles the numba kernels) take minutes on a cold cache on a loaded machine.
BOUND_S = 600.0
RESEND_S = 2.0  # how often a node's state is asked again while a transition's answer is awaited
TRANSITION_STATES = {"configuring", "cleaningup", "shuttingdown", "activating", "deactivating", "errorprocessing"}


class BringUpError(RuntimeError):
    """A node refused or did not answer a transition, or the bring-up was given up."""


class LifecycleClient(OwnNode):
    """Asks nodes, by name, for lifecycle transitions and their state; ``give_up()`` says why
    to stop waiting (a node that exited, a signal) or None.

    A request or its answer can be lost to a node that has just started (seen under load: a
    driver that never received its configure). So the node's state is asked every RESEND_S
    while a transition is awaited: the transition is done when an answer says so or the state
    is its goal, refused when every request was answered no and the state, asked after them,
    is not the goal; and the request is sent again when the node, RESEND_S after it, still
    answers from a state that is neither the goal nor a transition.
    """

    def __init__(self, ros_args: Sequence[str], give_up: Callable[[], str | None]):
        super().__init__("mows-graph", "mows_graph", ros_args)
        self._give_up = give_up
        self._clients: dict = {}

    def request(self, name: str, transition_id: int) -> Future:
        """Ask ``name`` for a transition (lifecycle_msgs/Transition id); the future of its answer."""
        client = self._client(ChangeState, f"{name}/change_state")
        self._wait(client.service_is_ready, BOUND_S, f"the lifecycle services of {name}")
        return client.call_async(ChangeState.Request(transition=Transition(id=transition_id)))

    def settle(self, name: str, transition_id: int, goal: str, sent: Future | None = None) -> bool:
        """Take ``name`` through ``transition_id`` to state ``goal`` (``sent``: its request,
        if sent already); whether it succeeded."""
        requests = [(time.monotonic(), sent or self.request(name, transition_id))]
        state = self._state_poll(name)

        def decided() -> tuple[bool] | None:
            asked_s, label = state()
            if label == goal or any(r.done() and r.result().success for _, r in requests):
                return (True,)
            last_s = requests[-1][0]
            if all(r.done() for _, r in requests):
                return (False,) if asked_s > last_s else None  # a refusal, once the state confirms it
            if asked_s > last_s + RESEND_S and label not in TRANSITION_STATES and not requests[-1][1].done():
                requests.append((time.monotonic(), self.request(name, transition_id)))  # lost: again
            return None

        return self._wait(decided, BOUND_S, f"{name} to become {goal}")[0]

    def transition(self, name: str, transition_id: int, goal: str) -> bool:
        """Take ``name`` through a transition to state ``goal``; whether it succeeded."""
        return self.settle(name, transition_id, goal)

    def state(self, name: str) -> str:
        """The state of ``name`` (its label: unconfigured, inactive, active, finalized, …)."""
        state = self._state_poll(name)
        return self._wait(lambda: state()[1], BOUND_S, f"the state of {name}")

    def _state_poll(self, name: str) -> Callable[[], tuple[float, str]]:
        """A function giving (when asked, state) of ``name`` from the newest answered of the
        GetState calls it sends (again every RESEND_S); (−inf, '') before the first answer."""
        client = self._client(GetState, f"{name}/get_state")
        calls: list[tuple[float, Future]] = []

        def poll() -> tuple[float, str]:
            if client.service_is_ready() and (not calls or time.monotonic() - calls[-1][0] > RESEND_S):
                calls.append((time.monotonic(), client.call_async(GetState.Request())))
            answered = [(asked_s, call.result()) for asked_s, call in calls if call.done()]
            return (answered[-1][0], answered[-1][1].current_state.label) if answered else (-math.inf, "")

        return poll

    def _client(self, kind, service: str):
        if service not in self._clients:
            self._clients[service] = self.node.create_client(kind, service)
        return self._clients[service]

    def _wait(self, condition: Callable[[], object], bound_s: float, what: str):
        deadline = time.monotonic() + bound_s
        while not (value := condition()):
            if (why := self._give_up()) is not None:
                raise BringUpError(f"{why} while waiting for {what}")
            if time.monotonic() > deadline:
                raise BringUpError(f"gave up after {bound_s:g} s waiting for {what}")
            self.executor.spin_once(timeout_sec=0.1)
        return value


def bring_up(
    names: Sequence[str], ros_args: Sequence[str], give_up: Callable[[], str | None], report: Callable[[str], None]
) -> None:
    """Configure every node of ``names`` at once, then activate them in their order; ``report``
    is told each step done."""
    client = LifecycleClient(ros_args, give_up)
    try:
        configure = Transition.TRANSITION_CONFIGURE
        configuring = {name: client.request(name, configure) for name in names}
        for name, sent in configuring.items():
            if not client.settle(name, configure, "inactive", sent):
                raise BringUpError(f"{name} refused to configure (its log and /diagnostics say why)")
        report(f"configured: {', '.join(names)}")
        for name in names:
            if not client.transition(name, Transition.TRANSITION_ACTIVATE, "active"):
                raise BringUpError(f"{name} refused to activate (its log and /diagnostics say why)")
            report(f"{name} active")
    finally:
        client.close()
