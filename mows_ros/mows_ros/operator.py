"""The operator of a stage without a motor, as a node sees them: a ``confirm_orientation``
service (std_srvs/Trigger) that a waiting sweep or calibration awaits after asking for a turn
in its action feedback (``orientation: manual``)."""

import dataclasses
import math
from collections.abc import Callable

from std_srvs.srv import Trigger

from mows.sweep.operator import turn_prompt
from mows_ros.awaitables import until
from mows_ros.diagnostics import Health
from mows_ros.params import ParamSpec

PARAMETERS = (  # of every node whose goals turn the probe
    ParamSpec(
        "orientation",
        "stage",
        "how the probe is turned: stage (the driver's stage turns it) or manual (a stage without a motor: "
        "the action's feedback asks the operator to turn it, ~/confirm_orientation continues)",
        choices=("stage", "manual"),
    ),
    ParamSpec(
        "confirm_timeout_s", 600.0, "orientation manual: longest wait for the operator's turn, s", range=(1.0, 86400.0)
    ),
)


AWAITED_TURN_KEY = "awaited_turn_deg"  # on /diagnostics
HOW_TO_CONFIRM = "Enter in mows-graph's terminal, mows-confirm-orientation, or the ~/confirm_orientation service"


class OperatorTurns:
    """``~/confirm_orientation`` of ``node`` under ``service``; ``awaited()`` is the orientation
    (rad) the running goal has asked the operator for, None when it asks for none."""

    def __init__(self, node, service: str, awaited: Callable[[], float | None]):
        self._node = node
        self._awaited = awaited
        self._confirmed = False
        node.create_service(Trigger, service, self._confirm)

    def _confirm(self, _, response: Trigger.Response) -> Trigger.Response:
        theta0 = self._awaited()
        response.success = theta0 is not None and not self._confirmed
        self._confirmed = self._confirmed or response.success
        response.message = (
            f"θ0 = {math.degrees(theta0):g}° confirmed" if response.success else "no turn of the probe is awaited"
        )
        return response

    def reported(self, health: Health) -> Health:
        """``health`` with the turn awaited, if any (``awaited_turn_deg``, '' for none): what a
        confirmation whose answer was lost checks (mows_bringup.confirm)."""
        theta0 = self._awaited()
        awaited = "" if theta0 is None or self._confirmed else f"{math.degrees(theta0):g}"
        return dataclasses.replace(health, values={**health.values, AWAITED_TURN_KEY: awaited})

    async def confirmed(self, timeout_s: float, cancelled: Callable[[], bool]) -> bool:
        """Await the operator's confirmation (True) or a cancel (True: the caller sees it);
        False after ``timeout_s`` of neither."""
        self._confirmed = False
        theta0 = self._awaited()
        if theta0 is not None:
            self._node.get_logger().info(f"{turn_prompt(theta0)}: {HOW_TO_CONFIRM}")
        return await until(self._node, lambda: self._confirmed or cancelled(), timeout_s)
