"""The calibrator node: the paper's probe calibration (Fig. 3) as an action, writing a probe file.

Names are relative (here as in the root namespace). Action ``/calibrator/calibrate_probe``
(CalibrateProbe; the previous release's ``/mows/calibrator/calibrate_probe`` too) runs
:class:`mows.sweep.calibration.run.CalibrationRun` through the driver: its supply
(``/driver/set_field_current``), its cycles (``/driver/measurement_cycle``, cancelled with the
goal), their fits (``/mows/ringdown``); docs/nodes.md has the goal, its endings, a manual stage
and ``probe_id``. A goal the node cannot run (inactive, a plan it refuses, a driver without a
supply, found by setting it to zero first, a plan outside the range the driver's answer states)
is accepted and aborted at once with the reason, before any other current is set. From the
sweeps kept, :class:`mows.sweep.calibration.run.ProbeCalibrator` writes the probe file. A run
whose client has left the graph (``mows_ros.requesters``) is cancelled, its cycle with it, and
ends aborted (it was never asked to cancel); every cancel and abort is logged and counted on
/diagnostics.

The node translates only; it runs on one thread and awaits the driver's answers as coroutines.
"""

import math

from diagnostic_msgs.msg import DiagnosticStatus
from mows_msgs.action import CalibrateProbe
from mows_msgs.msg import RingdownFit
from mows_msgs.srv import SetFieldCurrent
from rclpy.action import CancelResponse

from mows.device.cycle.phases import CycleRequest
from mows.estimate.calibration.fit_constants import CalibrationError
from mows.sim.scenario import load_scenario
from mows.sweep.calibration.run import CalibrationRun, ProbeCalibrator, Turn, goal_plan
from mows_calibrator.messages import calibrated, feedback_msg, fit_of, result_msg, supply_answer, supply_range
from mows_calibrator.parameters import PARAMETERS, bench_of
from mows_ros.awaitables import call
from mows_ros.cycles import DriverCycles
from mows_ros.diagnostics import Health
from mows_ros.goals import action_servers, end_goal
from mows_ros.node import MowsNode
from mows_ros.operator import OperatorTurns
from mows_ros.params import parameter_values
from mows_ros.process import run_node
from mows_ros.requesters import RequesterWatch, send_goal_services
from mows_ros.wall import steady_timer

NODE_NAME = "calibrator"
ACTIONS = ("~/calibrate_probe", "mows/calibrator/calibrate_probe")  # the node's own, the previous release's
SUPPLY_SERVICE = "driver/set_field_current"  # the driver's, in this node's namespace
WATCH_S = 0.1  # how often a running calibration looks for its client in the graph


class CalibratorNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self._calibrator = ProbeCalibrator()
        self._driver = DriverCycles(self, self._on_fit)
        group = self._driver.group
        self._supply = self.create_client(SetFieldCurrent, SUPPLY_SERVICE, callback_group=group)
        self._servers = action_servers(self, CalibrateProbe, ACTIONS, self._execute, self._cancel, group)
        self._operator = OperatorTurns(self, "~/confirm_orientation", lambda: self._calibrator.turn_awaited)
        self._client_gone = ""  # why the running calibration is cancelled by the node itself
        self.cancels, self.last_ending = 0, ""  # for /diagnostics

    def _param(self, name):
        return self.get_parameter(name).value

    # --- inputs ---------------------------------------------------------------------------
    def _on_fit(self, msg: RingdownFit):
        """The run's step once the fits of its cycle are in (None before, and between goals)."""
        run = self._calibrator.run
        if run is None or msg.tuning or not self._calibrator.calibrates(msg.probe_id):
            return None
        try:
            fit = fit_of(msg)
        except ValueError:
            self.get_logger().warning(f"a ring-down fit with the unknown status {msg.status} was left out")
            return None
        return run.on_fit(msg.cycle_id, fit)

    async def _refusal(self, goal) -> str | None:
        """Why ``goal`` is refused, or None when its run is accepted (the calibrator is busy
        from here): the plan, then the driver's answer to the supply set to zero."""
        if (inactive := self.inactive_reason()) is not None:
            return inactive
        try:
            homogeneous = load_scenario(self._param("scenario")).supply.name
            plan = goal_plan(goal, homogeneous, self._param("currents_a"))
            self._calibrator.accept(plan, self._param("orientation") == "manual", self._param("probe_id"))
        except ValueError as error:
            return str(error)
        request = SetFieldCurrent.Request(current_a=0.0)
        response = await call(self, self._supply, request, self._param("supply_timeout_s"))
        return self._calibrator.on_zero_supply(*supply_answer(response), *supply_range(response))

    def _cancel(self, _) -> CancelResponse:
        self._driver.cancel()
        return CancelResponse.ACCEPT

    def _watch(self, watch: RequesterWatch) -> None:
        """Cancel the calibration once every client that may wait for it has left the graph."""
        if not self._client_gone and watch.gone():
            self._client_gone = watch.reason
            self.get_logger().warning(f"calibration cancelled, its cycle with it: {self._client_gone}")
            self._driver.cancel()

    # --- the calibration --------------------------------------------------------------------
    async def _execute(self, goal_handle):
        if (refusal := await self._refusal(goal_handle.request)) is not None:
            message = f"calibration goal refused: {refusal}"
            self.get_logger().warning(message)
            goal_handle.abort()
            return CalibrateProbe.Result(success=False, message=message, supply_at_zero=False)
        run = self._calibrator.run
        self._client_gone = ""
        watch = RequesterWatch(self, send_goal_services(self, ACTIONS))
        timer = steady_timer(self, WATCH_S, lambda: self._watch(watch), callback_group=self._driver.group)

        def cancelled() -> bool:
            return goal_handle.is_cancel_requested or bool(self._client_gone)

        try:
            step = run.start()
            while step.outcome is None:
                for feedback in step.feedback:
                    goal_handle.publish_feedback(feedback_msg(feedback))
                if cancelled():
                    step = run.cancel(self._client_gone or "cancelled by the client") or step
                step = await self._act(run, step, cancelled)
            return self._finish(goal_handle, step.outcome)
        finally:
            self.destroy_timer(timer)
            self._calibrator.release()

    async def _act(self, run: CalibrationRun, step, cancelled):
        (action,) = step.actions
        if isinstance(action, Turn):
            timeout_s = self._param("confirm_timeout_s")
            if await self._operator.confirmed(timeout_s, cancelled):
                return step if cancelled() else run.on_turned()  # a cancel is taken at the loop's top
            return run.cancel(f"no confirmation of θ0 = {math.degrees(action.theta0_rad):g}° within {timeout_s:g} s")
        if isinstance(action, CycleRequest):
            answered = run.on_cycle(await self._driver.run(action, self._param("cycle_timeout_s"), cancelled))
            return answered or await self._driver.fits(self._param("fit_timeout_s"), run.fits_time_up)
        request = SetFieldCurrent.Request(current_a=float(action.current_a))
        return run.on_supply(*supply_answer(await call(self, self._supply, request, self._param("supply_timeout_s"))))

    def _finish(self, goal_handle, outcome) -> CalibrateProbe.Result:
        result = result_msg(outcome, self._calibrator.others)
        # A cancel that cut the running cycle short ends the run as that cycle's failure.
        if outcome.cancelled or goal_handle.is_cancel_requested or self._client_gone:
            self.cancels, self.last_ending = self.cancels + 1, f"cancelled: {result.message}"
            self.get_logger().info(f"calibration {self.last_ending}")
            end_goal(goal_handle, False, cancelled=True)
            return result
        if not outcome.success:
            self.last_ending = f"aborted: {result.message}"
            self.get_logger().warning(f"calibration {self.last_ending}")
            goal_handle.abort()
            return result
        self._calibrator.keep(outcome)
        path = goal_handle.request.probe_output_file or self._param("probe_output_file")
        try:
            calibration, written = self._calibrator.write_probe(bench_of(parameter_values(self, PARAMETERS)), path)
        except (CalibrationError, ValueError, OSError) as error:
            result.message = self._calibrator.last = f"{result.message}; calibration: {error}"
            self.last_ending = f"aborted: {result.message}"
            self.get_logger().warning(f"calibration {self.last_ending}")
            goal_handle.abort()
            return result
        self.get_logger().info(f"probe file: {written}")
        self.get_logger().info(f"{self._calibrator.last}\n{calibration.report()}")
        self.last_ending = "succeeded"
        goal_handle.succeed()
        return calibrated(result, calibration, path)

    def health(self) -> Health:
        values = {
            "state": self._calibrator.state,
            "calibrations": self._calibrator.calibrations,
            "cancels": self.cancels,
            "last_ending": self.last_ending,
        }
        return self._operator.reported(Health(DiagnosticStatus.OK, self._calibrator.last, values))


def main(args: list[str] | None = None) -> int:
    return run_node(CalibratorNode, args)
