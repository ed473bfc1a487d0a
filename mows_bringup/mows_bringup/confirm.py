"""mows-confirm-orientation: the operator of a stage without a motor says the probe is turned.

A sweep (the mapper) or a calibration (the calibrator) with ``orientation: manual`` asks, before
each cycle, for the probe to be turned by hand (its log and its action feedback say to which θ0)
and waits for the operator. This confirms the turn to each node that awaits one, in the graph's
namespace (``--ros-args -r __ns:=/probe_a``), and prints each node's answer. ``mows-graph`` does
the same when Enter is pressed in its terminal.

Which turn a node awaits is on its /diagnostics (``awaited_turn_deg``); the confirmation is its
``confirm_orientation`` service (std_srvs/Trigger). DDS drops a service's answer to a client it
has not matched yet, and this command's node is new: when the answer is lost, the node's next
report says whether the confirmation arrived (the turn is no longer awaited), and the request is
sent again only when it did not, so that one command never confirms two turns.

    mows-confirm-orientation [--ros-args -r __ns:=/probe_a]

Exit status: 0 when a turn was awaited and is now confirmed; 1 when no node awaited one (or
none answered within ANSWER_S); 2 for an unknown argument.
"""

import sys
import time
from collections.abc import Callable

from diagnostic_msgs.msg import DiagnosticArray
from std_srvs.srv import Trigger

from mows_bringup.own_node import OwnNode
from mows_ros.operator import AWAITED_TURN_KEY

TURNING_NODES = ("mapper", "calibrator")  # the nodes whose goals turn the probe
ANSWER_S = 10.0  # longest wait for discovery, a node's report and its answer (a node answers at once)
LOST_S = 3.0  # an answer not here by then is lost
REPORT_S = 1.5  # a report this long after a request shows what became of it (reports come at 1 Hz)
SENDS = 3  # requests at most, each sent only when the one before never arrived


class Operator(OwnNode):
    """A node of its own that hears the turning nodes' reports and calls their services."""

    def __init__(self, ros_args: list[str]):
        super().__init__("mows-confirm-orientation", "mows_operator", ros_args)
        self.reports: dict[str, tuple[float, str]] = {}  # node → (when heard, the turn it awaits)
        self.node.create_subscription(DiagnosticArray, "/diagnostics", self._heard, 10)
        self.deadline = time.monotonic() + ANSWER_S

    def _heard(self, array: DiagnosticArray) -> None:
        namespace = self.node.get_namespace().rstrip("/")
        for status in array.status:
            name = status.name.removeprefix(f"{namespace}/")
            values = {kv.key: kv.value for kv in status.values}
            if name in TURNING_NODES and AWAITED_TURN_KEY in values:
                self.reports[name] = (time.monotonic(), values[AWAITED_TURN_KEY])

    def spin_until(self, condition: Callable[[], object], until_s: float) -> object:
        """Spin until ``condition()`` is true (its value) or the monotonic time ``until_s``."""
        while not (value := condition()) and time.monotonic() < min(until_s, self.deadline):
            self.executor.spin_once(timeout_sec=0.05)
        return value

    def confirm(self, name: str) -> tuple[bool, str]:
        """Confirm the turn ``name`` awaits: whether it was awaited and is confirmed, and what it said."""
        if not self.spin_until(lambda: name in self.reports, self.deadline):
            return False, "no report on /diagnostics (is it running?)"
        awaited = self.reports[name][1]
        if not awaited:
            return False, "no turn of the probe is awaited"
        client = self.node.create_client(Trigger, f"{name}/confirm_orientation")
        if not self.spin_until(client.service_is_ready, self.deadline):
            return False, "its confirm_orientation service did not appear"
        for _ in range(SENDS):
            sent_s = time.monotonic()
            call = client.call_async(Trigger.Request())
            if self.spin_until(call.done, sent_s + LOST_S):
                answer = call.result()
                return answer.success, answer.message
            # The answer was lost: the node's next report says whether the request arrived.
            if not self.spin_until(lambda s=sent_s: self.reports[name][0] > s + REPORT_S, self.deadline):
                break
            if self.reports[name][1] != awaited:
                return True, f"θ0 = {awaited}° confirmed (its answer was lost; its report shows the turn taken)"
        return False, "no answer"


def confirm_turn(ros_args: list[str]) -> tuple[bool, list[str]]:
    """Confirm the turn that each node of TURNING_NODES awaits, in the namespace ``ros_args``
    give: whether one awaited one, and one line per node ("mapper: θ0 = 90° confirmed")."""
    operator = Operator(ros_args)
    try:
        answers = {name: operator.confirm(name) for name in TURNING_NODES}
    finally:
        operator.close()
    return any(ok for ok, _ in answers.values()), [f"{name}: {said}" for name, (_, said) in answers.items()]


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    own = argv[: argv.index("--ros-args")] if "--ros-args" in argv else argv
    if own in (["-h"], ["--help"]):
        print(__doc__)
        return 0
    if own:
        print(f"mows-confirm-orientation: error: unrecognized arguments: {' '.join(own)} (see --help)", file=sys.stderr)
        return 2
    confirmed, lines = confirm_turn(argv[argv.index("--ros-args") + 1 :] if "--ros-args" in argv else [])
    for line in lines:
        print(line)
    return 0 if confirmed else 1


if __name__ == "__main__":
    sys.exit(main())
