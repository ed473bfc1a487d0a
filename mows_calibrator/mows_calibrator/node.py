"""The calibrator node: the paper's probe calibration (Fig. 3) as an action, writing a probe file.

Names are relative (here as in the root namespace). Action ``/mows/calibrator/calibrate_probe``
(CalibrateProbe) runs :class:`mows.sweep.calibration_schedule.CalibrationSchedule`: it steps the
driver's static-field supply (``/mows/driver/set_field_current``), runs one driver cycle per
orientation at each current (``/mows/driver/run_cycle``), collects that cycle's ring-down fits
(``/mows/ringdown``) and sends feedback per cycle. Every ending, cancelled or failed, ramps the
supply back to zero before the result is returned. With the homogeneous wiring's points it fits
the constants (:func:`mows.estimate.probe_calibration.calibrate_probe`) and writes the probe file
that the estimator and the mapper load by ``probe_file``; gradient points of an earlier goal
(``wiring: gradient``) add the lever check.

The node translates only; it runs on one thread and awaits the driver's answers as coroutines.
"""

import datetime
import math
import time

from diagnostic_msgs.msg import DiagnosticStatus
from mows_msgs.action import CalibrateProbe
from mows_msgs.msg import RingdownFit
from mows_msgs.srv import RunCycle, SetFieldCurrent
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.task import Future

from mows.estimate.probe_calibration import CalibrationError, KnownConstants, calibrate_probe
from mows.estimate.ringdown import SETTLE_S, FitStatus
from mows.estimate.ringdown import RingdownFit as Fit
from mows.physics.probe import PAPER_PROBE, Probe
from mows.sim.scenario import load_scenario
from mows.sweep.calibration_schedule import (
    GRADIENT_WIRING,
    PAPER_CURRENTS_A,
    CalibrationPlan,
    CalibrationSchedule,
    scenario_wirings,
)
from mows.sweep.calibration_schedule import RunCycle as Cycle
from mows_ros.diagnostics import Health
from mows_ros.node import MowsNode
from mows_ros.params import ParamSpec
from mows_ros.probe import probe_file_problem
from mows_ros.process import run_node
from mows_ros.qos import RESULT_QOS

NODE_NAME = "calibrator"
ACTION = "mows/calibrator/calibrate_probe"


def scenario_problem(parameter: str, name: str) -> str | None:
    """Why ``name`` is no scenario with a supply section, or None ('' is allowed: none)."""
    try:
        if name and load_scenario(name).supply is None:
            return f"{parameter}={name!r} has no supply section: the supply's field per ampere is unknown"
    except (OSError, ValueError) as error:
        return f"{parameter}={name!r}: {error}"
    return None


def nominal_probe_problem(path: str) -> str | None:
    """Why ``nominal_probe_file`` cannot be read, or None ('' is the paper's probe)."""
    problem = probe_file_problem(path) if path else None
    return None if problem is None else f"nominal_{problem}"  # probe_file_problem says probe_file=…


PARAMETERS = (
    ParamSpec(
        "scenario",
        "calibration",
        "scenario whose supply section describes the homogeneous wiring (the "
        "Helmholtz pair's field per ampere at the probe)",
        check=lambda v: scenario_problem("scenario", v or "?"),
    ),
    ParamSpec(
        "gradient_scenario",
        "calibration_gradient",
        "scenario whose supply section describes the gradient wiring (anti-Helmholtz); '' for none",
        check=lambda v: scenario_problem("gradient_scenario", v),
    ),
    ParamSpec(
        "nominal_probe_file",
        "",
        "probe YAML giving the magnet's moment, mass and the housing stop ('' the paper's)",
        check=nominal_probe_problem,
    ),
    ParamSpec("probe_file", "calibrated_probe.yaml", "where a goal without probe_file writes the calibrated probe"),
    ParamSpec("hardware_id", "", "written to the probe file ('' the scenario's name)"),
    ParamSpec("currents_a", list(PAPER_CURRENTS_A), "supply currents of a goal that lists none, A"),
    ParamSpec("cycle_timeout_s", 300.0, "longest wait for the driver's cycle, s", range=(1.0, 3600.0)),
    ParamSpec("supply_timeout_s", 60.0, "longest wait for the supply to reach a current, s", range=(1.0, 3600.0)),
    ParamSpec("fit_timeout_s", 10.0, "longest wait for the fits of a finished cycle, s", range=(0.1, 600.0)),
)


def fit_of(msg: RingdownFit) -> Fit:
    """The estimator's fit as the core's result (what the schedule and the calibration read)."""
    return Fit(
        status=FitStatus(msg.status),
        message=msg.message,
        theta0_rad=msg.theta0_rad,
        frequency_hz=msg.frequency_hz,
        frequency_std_hz=msg.frequency_std_hz,
        damping_per_s=msg.damping_per_s,
        amplitude_rad=msg.amplitude_rad,
        duration_s=msg.duration_s,
        start_offset_s=SETTLE_S,
    )


class CalibratorNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        group = ReentrantCallbackGroup()
        self._fits: dict[int, list] = {}
        self._waiting: tuple[int, int, Future] | None = None  # (cycle id, fits wanted, resolved when there)
        self._points: dict[str, tuple] = {}  # wiring → points of its last complete sweep
        self._busy = False
        self._last = "no calibration yet"
        self._calibrations = 0
        self.create_subscription(RingdownFit, "mows/ringdown", self._on_fit, RESULT_QOS, callback_group=group)
        self._supply = self.create_client(SetFieldCurrent, "mows/driver/set_field_current", callback_group=group)
        self._cycle = self.create_client(RunCycle, "mows/driver/run_cycle", callback_group=group)
        self._server = ActionServer(
            self,
            CalibrateProbe,
            ACTION,
            self._execute,
            goal_callback=self._accept,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=group,
        )

    def _param(self, name):
        return self.get_parameter(name).value

    # --- inputs ---------------------------------------------------------------------------
    def _on_fit(self, msg: RingdownFit) -> None:
        if not self._busy or msg.tuning:
            return
        if msg.status not in set(FitStatus):
            self.get_logger().warning(f"a ring-down fit with the unknown status {msg.status} was left out")
            return
        fits = self._fits.setdefault(msg.cycle_id, [])
        fits.append(fit_of(msg))
        if self._waiting and self._waiting[0] == msg.cycle_id and len(fits) >= self._waiting[1]:
            if not self._waiting[2].done():
                self._waiting[2].set_result(True)

    def _accept(self, goal) -> GoalResponse:
        try:
            self._plan(goal)
        except ValueError as error:
            self.get_logger().warning(f"calibration goal refused: {error}")
            return GoalResponse.REJECT
        if self._busy:
            self.get_logger().warning("calibration goal refused: a calibration is running")
            return GoalResponse.REJECT
        self._busy = True
        return GoalResponse.ACCEPT

    def _plan(self, goal) -> CalibrationPlan:
        wiring = goal.wiring or load_scenario(self._param("scenario")).supply.name
        if goal.wiring and goal.wiring != GRADIENT_WIRING:
            raise ValueError(f"wiring {goal.wiring!r}: '' (homogeneous) or {GRADIENT_WIRING!r}")
        return CalibrationPlan(
            tuple(goal.currents_a) or tuple(self._param("currents_a")),
            tuple(goal.theta0_rad) or (0.0, math.pi),
            int(goal.repeats) or 1,
            wiring,
        )

    # --- the calibration --------------------------------------------------------------------
    async def _execute(self, goal_handle):
        try:
            plan = self._plan(goal_handle.request)
            self._fits.clear()
            schedule = CalibrationSchedule(plan)
            step = schedule.start()
            while step.outcome is None:
                for feedback in step.feedback:
                    goal_handle.publish_feedback(
                        CalibrateProbe.Feedback(
                            step=feedback.step,
                            steps=feedback.steps,
                            current_a=feedback.current_a,
                            theta0_rad=feedback.theta0_rad,
                            ringdowns=feedback.ringdowns,
                            message=feedback.message,
                        )
                    )
                if goal_handle.is_cancel_requested:
                    cancelled = schedule.cancel("cancelled by the client")
                    step = cancelled if cancelled.actions else step  # already on its way to zero
                step = await self._act(schedule, step)
            return self._finish(goal_handle, plan, step.outcome)
        finally:
            self._busy = False

    async def _act(self, schedule, step):
        (action,) = step.actions
        if isinstance(action, Cycle):
            return await self._cycle_step(schedule, action)
        return await self._supply_step(schedule, action.current_a)

    async def _supply_step(self, schedule, current_a: float):
        response = await self._call(
            self._supply, SetFieldCurrent.Request(current_a=float(current_a)), self._param("supply_timeout_s")
        )
        if response is None:
            return schedule.on_supply(False, "no answer from the driver's set_field_current")
        return schedule.on_supply(response.success, response.message)

    async def _cycle_step(self, schedule, action: Cycle):
        request = RunCycle.Request(
            theta0_rad=float(action.theta0_rad), repeats=int(action.repeats), tuning_steps=-1, gap_s=-1.0
        )
        response = await self._call(self._cycle, request, self._param("cycle_timeout_s"))
        if response is None or not response.success:
            return schedule.on_cycle_done(False, response.message if response else "no answer from the driver")
        await self._fits_of(response.cycle_id, response.ringdowns_recorded)
        for fit in self._fits.pop(response.cycle_id, [])[: action.repeats]:
            schedule.on_fit(fit)
        step = schedule.on_cycle_done(True)
        return step if step.actions or step.outcome else schedule.fits_timed_out()

    async def _fits_of(self, cycle_id: int, count: int) -> None:
        """Wait (up to fit_timeout_s) until ``count`` fits of ``cycle_id`` have arrived."""
        arrived = Future()
        if len(self._fits.get(cycle_id, [])) >= count:
            return
        self._waiting = (cycle_id, count, arrived)
        await self._within(arrived, self._param("fit_timeout_s"))
        self._waiting = None

    async def _call(self, client, request, timeout_s: float):
        deadline = time.monotonic() + timeout_s
        while not client.service_is_ready():  # the driver may not be discovered yet
            if time.monotonic() > deadline:
                return None
            await self._within(Future(), 0.1)
        future = client.call_async(request)
        return future.result() if await self._within(future, timeout_s) else None

    async def _within(self, future: Future, timeout_s: float) -> bool:
        """Await ``future`` for at most ``timeout_s``; whether it completed."""
        waiter = Future()
        future.add_done_callback(lambda _: waiter.done() or waiter.set_result(True))
        timer = self.create_timer(timeout_s, lambda: waiter.done() or waiter.set_result(False))
        try:
            return await waiter
        finally:
            self.destroy_timer(timer)

    def _finish(self, goal_handle, plan: CalibrationPlan, outcome) -> CalibrateProbe.Result:
        result = CalibrateProbe.Result(success=False, message=outcome.message, supply_at_zero=outcome.supply_at_zero)
        if outcome.cancelled:
            goal_handle.canceled()
            return result
        if not outcome.success:
            goal_handle.abort()
            return result
        self._points[plan.wiring] = (outcome.points, outcome.failed)
        try:
            calibration, path = self._calibrate(goal_handle.request.probe_file or self._param("probe_file"))
        except (CalibrationError, ValueError, OSError) as error:
            result.message = f"{outcome.message}; calibration: {error}"
            self._last = result.message
            goal_handle.abort()
            return result
        self._calibrations += 1
        self._last = f"calibration {self._calibrations}: {calibration.report().splitlines()[0]} → {path}"
        self.get_logger().info(f"{self._last}\n{calibration.report()}")
        result.success, result.message, result.probe_file = True, f"{outcome.message}; probe file {path}", path
        result.names = list(calibration.names)
        result.values = [float(v) for v in calibration.values]
        result.stds = [calibration.std(n) for n in calibration.names]
        goal_handle.succeed()
        return result

    def _calibrate(self, path: str):
        scenario = load_scenario(self._param("scenario"))
        gradient = load_scenario(self._param("gradient_scenario")) if self._param("gradient_scenario") else None
        nominal = (
            Probe.from_yaml(self._param("nominal_probe_file")) if self._param("nominal_probe_file") else PAPER_PROBE
        )
        if scenario.supply.name not in self._points:
            raise ValueError("no sweep of the homogeneous wiring yet: β0 needs one")
        points, failed = [], {}
        for wiring_points, wiring_failed in self._points.values():
            points += wiring_points
            failed.update(wiring_failed)
        calibration = calibrate_probe(
            points,
            scenario_wirings(scenario, gradient),
            KnownConstants.of(nominal),
            scenario.supply.name,
            failed,
            nominal.lever_m,
        )
        date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
        calibration.probe().to_yaml(path, calibration.record(date, self._param("hardware_id") or scenario.name))
        return calibration, path

    def health(self) -> Health:
        return Health(
            DiagnosticStatus.OK,
            self._last,
            {"state": "calibrating" if self._busy else "idle", "calibrations": self._calibrations},
        )


def main(args: list[str] | None = None) -> int:
    return run_node(CalibratorNode, args)
