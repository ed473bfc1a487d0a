"""The mapper node: rotation sweeps, their field/gradient decomposition, and the model lab.

Names are relative (here as in the root namespace). Action ``/mapper/rotation_sweep``
(RotationSweep; ``/mows/mapper/rotation_sweep``, the previous release's name, is served too for
one release) runs :class:`mows.sweep.runner.SweepRunner`: for each orientation one driver cycle
(its action ``/driver/measurement_cycle``, cancelled when the sweep ends without it) and that
cycle's fits (``/mows/ringdown``) as feedback; at the end the decomposition, and what
:func:`mows.sweep.publication.publication` says to publish: ``/mows/sweep`` (one per probe with
several ``probes``), ``/mows/field_map`` of several probes, and with ``reference_scenario`` the
model lab's ``/mows/model_report`` (docs/nodes.md, docs/multi_probe.md). With ``orientation``
manual each cycle waits for the operator's ``~/confirm_orientation`` (std_srvs/Trigger). A sweep
whose client has left the graph (``mows_ros.requesters``) is cancelled, its running cycle with
it, and ends aborted (it was never asked to cancel); every cancel and abort is logged and counted
on /diagnostics. Who asked, the cancels and what each ending reports are
:class:`mows.sweep.requests.SweepRequests`'s.

The node translates only. Everything runs on one thread: the action awaits the driver, the fits
and the CPU-bound decomposition and lab (in a worker thread) as a coroutine, so fits, cancels and
diagnostics are served meanwhile.
"""

import dataclasses

from mows_msgs.action import RotationSweep, WorkspaceMap
from mows_msgs.msg import RingdownFit
from rclpy.action import CancelResponse

from mows.device.cycle.phases import CycleRequest
from mows.estimate.settings import probe_set
from mows.sweep.events import CycleAnswer, SweepFit, SweepGoal, SweepOutcome, SweepStep
from mows.sweep.publication import Publication, cycle_failed, publication
from mows.sweep.requests import Cancel, LogLine, Severity, SweepRequests
from mows.sweep.runner import SweepRunner
from mows_mapper import messages, workspace
from mows_mapper.health import sweep_health
from mows_mapper.outputs import MapperOutputs
from mows_mapper.parameters import PARAMETERS, sweep_settings
from mows_mapper.workspace import ArmMapping
from mows_ros.awaitables import in_worker, until
from mows_ros.cycles import DriverCycles
from mows_ros.diagnostics import Health
from mows_ros.goals import action_servers, end_goal
from mows_ros.node import MowsNode
from mows_ros.operator import OperatorTurns
from mows_ros.params import parameter_values
from mows_ros.probe import probe_of
from mows_ros.process import run_node
from mows_ros.requesters import request_writers, send_goal_services, steady_s
from mows_ros.wall import steady_timer

NODE_NAME = "mapper"
SERVICE_WAIT_S = 5.0  # longest wait for the driver's measurement-cycle action to appear
ACTIONS = ("~/rotation_sweep", "mows/mapper/rotation_sweep")  # the node's own, the previous release's
WATCH_S = 0.1  # how often a running sweep looks for its client in the graph
MAP_ACTIONS = (workspace.ACTION,)


class _NoFeedback:
    """A workspace map's sweeps report through the map's own feedback."""

    def publish_feedback(self, _) -> None:
        pass


class MapperNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self._runner = SweepRunner()
        self._requests = SweepRequests(self._runner)
        self._driver = DriverCycles(self, self._on_fit)
        probes = probe_set(self._param("probes"), probe_of(self._param("probe_file")))
        self._outputs = MapperOutputs(self, len(probes))
        self._servers = action_servers(self, RotationSweep, ACTIONS, self._execute, self._cancel, self._driver.group)
        self._operator = OperatorTurns(self, "~/confirm_orientation", lambda: self._runner.turn_awaited)
        self._mapping = ArmMapping(self, lambda: parameter_values(self, PARAMETERS), self._map_sweep)
        self._map_servers = action_servers(
            self, WorkspaceMap, MAP_ACTIONS, self._execute_map, self._cancel_map, self._driver.group
        )
        self._arm_turn: workspace.Turn | None = None

    def _param(self, name):
        return self.get_parameter(name).value

    # --- inputs ---------------------------------------------------------------------------
    def _on_fit(self, msg: RingdownFit) -> SweepStep | None:
        return self._runner.on_fit(SweepFit.from_message(msg))

    def _refusal(self, goal: RotationSweep.Goal) -> str | None:
        """Why ``goal`` is refused, or None when the sweep starts (the runner is busy from here)."""
        if (refusal := self.inactive_reason() or self._requests.sweep_refusal()) is not None:
            return refusal
        try:
            settings = sweep_settings(parameter_values(self, PARAMETERS), probe_of(self._param("probe_file")))
            self._runner.start(messages.sweep_goal(goal), settings)
        except ValueError as refused:
            return str(refused)
        return None

    def _cancel(self, _) -> CancelResponse:
        return self._carry_out(self._requests.on_cancel())

    def _cancel_map(self, _) -> CancelResponse:
        return self._carry_out(self._requests.on_cancel_map())

    def _watch(self) -> None:
        present = request_writers(self, self._requests.service_names)
        self._carry_out(self._requests.on_graph(present, steady_s()))

    def _carry_out(self, cancel: Cancel | None) -> CancelResponse:
        """The running cycle cancelled and the fits of a cycle that has ended no longer awaited:
        the sweep ends at once (nothing, and the cancel refused, for None)."""
        if cancel is None:
            return CancelResponse.REJECT
        self._log(cancel.log)
        self._driver.cancel()
        self._driver.deliver(cancel.step)
        return CancelResponse.ACCEPT

    def _log(self, line: LogLine | None) -> None:
        # One call site per severity: rclpy refuses to change a call site's severity.
        if line is not None and line.severity == Severity.INFO:
            self.get_logger().info(line.text)
        elif line is not None:
            self.get_logger().warning(line.text)

    # --- the sweep ------------------------------------------------------------------------
    async def _execute(self, goal_handle):
        if (refusal := self._refusal(goal_handle.request)) is not None:
            result = messages.refused_result(f"sweep goal refused: {refusal}")
            self.get_logger().warn(result.message)
            goal_handle.abort()
            return result
        self.get_logger().info("sweep goal accepted")
        outcome, plan = await self._sweep(ACTIONS, lambda step: messages.step_feedback_msgs(step), goal_handle)
        result = messages.result_msg(outcome, self._param("frame_id"), plan.per_probe)
        end_goal(goal_handle, outcome.ok, outcome.cancelled)
        return result

    async def _sweep(self, actions, feedback_msgs, goal_handle) -> tuple[SweepOutcome, Publication]:
        """The started sweep run to its end and published, its client watched under ``actions``."""
        services = send_goal_services(self, actions)
        self._requests.watch(services, request_writers(self, services), steady_s())
        timer = steady_timer(self, WATCH_S, self._watch, callback_group=self._driver.group)
        try:
            step = self._runner.begin()
            while step.finished is None:
                for feedback in feedback_msgs(step):
                    goal_handle.publish_feedback(feedback)
                step = await self._advance(step)
            outcome = step.finished
            plan = publication(step, self._runner.settings, self._param("reference_scenario"))
            await self._publish(plan)
        finally:  # an exception must not leave the runner busy for good
            self.destroy_timer(timer)
            self._requests.abandon("the sweep ended unexpectedly (see the log)")
        self._log(self._requests.ended(outcome))
        return outcome, plan

    # --- the workspace map ------------------------------------------------------------------
    async def _execute_map(self, goal_handle):
        probe = probe_of(self._param("probe_file"))
        settings = sweep_settings(parameter_values(self, PARAMETERS), probe)
        if (refusal := self.inactive_reason() or self._requests.start_map(len(settings.probes))) is not None:
            goal_handle.abort()
            return WorkspaceMap.Result(success=False, message=f"workspace map refused: {refusal}")
        try:
            carried = settings.probes[0].probe
            result = await self._mapping.run(goal_handle, carried, lambda: self._requests.map_cancelled)
        except ValueError as error:  # no pose left within reach; sweeps that cannot determine a map
            result = WorkspaceMap.Result(success=False, message=f"workspace map failed: {error}")
        finally:
            self._requests.map_ended()
        if not result.success:
            self.get_logger().warning(result.message)
        end_goal(goal_handle, result.success, self._requests.map_cancelled)
        return result

    async def _map_sweep(self, goal: SweepGoal, arm_turn: workspace.Turn | None) -> SweepOutcome:
        """One rotation sweep of the workspace map where the arm holds the probe; ``arm_turn``
        turns it to each orientation when the arm's last joint does (no stage)."""
        try:
            settings = sweep_settings(parameter_values(self, PARAMETERS), probe_of(self._param("probe_file")))
            if arm_turn is not None:  # each orientation is the arm's: turned, then measured
                settings = dataclasses.replace(settings, manual_orientation=True)
            self._runner.start(goal, settings)
        except ValueError as refused:
            return SweepOutcome(False, f"sweep refused: {refused}")
        self._arm_turn = arm_turn
        try:
            outcome, _ = await self._sweep(MAP_ACTIONS, lambda _: (), _NoFeedback())
        finally:
            self._arm_turn = None
        return outcome

    async def _advance(self, step: SweepStep) -> SweepStep:
        if step.turn is not None:
            return await self._turned()
        if step.run_cycle is not None:
            return self._runner.on_cycle(await self._run_cycle(step.run_cycle))
        if step.decompose is not None:
            return self._runner.on_decomposed(await in_worker(self, step.decompose))
        # The cycle's fits are due: the step once they are in, or at fit_timeout_s.
        return await self._driver.fits(self._param("fit_timeout_s"), self._runner.fits_time_up)

    async def _turned(self) -> SweepStep:
        """The operator's confirmation (or a cancel) goes on with the sweep; silence ends it. In
        a workspace map whose arm turns the probe, the arm's turn instead."""
        if self._arm_turn is not None:
            problem = await self._arm_turn(self._runner.turn_awaited)
            return self._runner.abandon(problem) if problem else self._runner.on_turned()
        timeout_s = self._param("confirm_timeout_s")
        if await self._operator.confirmed(timeout_s, self._runner.cancelled):
            return self._runner.on_turned()
        return self._runner.turn_timed_out(timeout_s)

    async def _run_cycle(self, cycle: CycleRequest) -> CycleAnswer:
        if not await until(self, self._driver.ready, SERVICE_WAIT_S):
            return CycleAnswer(problem="the driver's measurement_cycle action is not available")
        answer = await self._driver.run(cycle, self._param("cycle_timeout_s"), self._runner.cancelled)
        return cycle_failed(answer)

    async def _publish(self, plan: Publication) -> None:
        """The sweep's maps (:class:`MapperOutputs`), then the model lab's report on the first."""
        published = self._outputs.publish(plan, self._param("frame_id"), self._runner.last)
        if plan.lab is None:
            return
        probe, auto = probe_of(self._param("probe_file")), self._param("lab_auto")
        try:
            report = await in_worker(self, lab_report, plan.lab, self._param("reference_scenario"), probe, auto)
        except ValueError as error:  # a table the lab cannot use is reported, not fatal
            self.get_logger().warn(f"model lab: {error}")
        else:
            self._outputs.publish_report(report, published[0])

    def health(self) -> Health:
        return self._operator.reported(sweep_health(self._runner))


def lab_report(sweep, reference: str, probe, auto: bool):
    """:func:`mows.lab.analyse_sweep`, run in a worker thread. The lab is imported at the first
    report, not at the node's start (a second of CPU for every mapper started)."""
    from mows.lab import analyse_sweep

    return analyse_sweep(sweep, reference, probe, auto)


def main(args: list[str] | None = None) -> int:
    return run_node(MapperNode, args)
