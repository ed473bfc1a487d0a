"""The mapper node: rotation sweeps, their field/gradient decomposition, and the model lab.

Names are relative (here as in the root namespace). Action ``/mapper/rotation_sweep``
(RotationSweep; ``/mows/mapper/rotation_sweep``, the previous release's name, is served too for
one release): for each orientation it asks the driver for one measurement cycle (its action
``/driver/measurement_cycle``, cancelled when the sweep ends without it), collects that cycle's
ring-down fits from the estimator (``/mows/ringdown``), reports them as feedback, and at the
end decomposes the sweep (``mows.sweep.decompose``) into in-plane field and gradient. The result is
published on ``/mows/sweep`` (SweepDecomposition, reliable and transient-local: a map). With a
reference (``reference_scenario``) the model lab (``mows.lab.analyse``) compares the
frequency model with the sweep and publishes ``/mows/model_report`` (ModelReport).

With ``probes`` listing several probes (the estimator's list), each ring-down brings one fit per
probe; each probe's sweep is decomposed with its neighbours' fields in the model
(:mod:`mows.sweep.probes`: each probe's external field and gradient) and published on
``/mows/sweep`` with its
``probe_id`` (frame ``<frame_id>_<probe_id>``), failed or not (the topic keeps one per probe),
and all of them together on ``/mows/field_map`` (FieldMap, reliable and transient-local), each
at its ``position_m`` in ``frame_id``. The model lab reads one probe's sweep: it is not run then.

With ``orientation`` manual (a stage without a motor) each cycle waits for the operator: the
feedback's ``operator_prompt`` says where to turn the probe, ``~/confirm_orientation``
(std_srvs/Trigger) says it is done.

The sweep itself is :class:`mows.sweep.runner.SweepRunner`; this node translates its steps.
Everything runs on one thread: the action awaits the driver, the fits and the CPU-bound
decomposition and lab (in a worker thread) as a coroutine, so fits, cancels and
diagnostics are served meanwhile.
"""

import dataclasses

from diagnostic_msgs.msg import DiagnosticStatus
from mows_msgs.action import RotationSweep
from mows_msgs.msg import FieldMap, ModelReport, RingdownFit, SweepDecomposition
from rclpy.action import CancelResponse

from mows.lab import analyse, from_sweep
from mows.sweep.runner import CycleAnswer, CycleRequest, SweepMap, SweepRunner, SweepSettings, SweepStep
from mows_mapper.messages import (
    feedback_msg,
    field_map_msg,
    model_report_msg,
    no_decomposition_msg,
    outcome_decomposition_msg,
    probe_decomposition_msg,
    sweep_fit,
    sweep_goal,
    turn_feedback_msg,
)
from mows_mapper.parameters import PARAMETERS, sweep_settings
from mows_ros.awaitables import in_worker, until
from mows_ros.cycles import DriverCycles
from mows_ros.diagnostics import Health
from mows_ros.goals import action_servers
from mows_ros.node import MowsNode
from mows_ros.operator import OperatorTurns
from mows_ros.params import parameter_values
from mows_ros.probe import probe_of, probe_set
from mows_ros.process import run_node
from mows_ros.qos import MAP_QOS, maps_qos

NODE_NAME = "mapper"
SERVICE_WAIT_S = 5.0  # longest wait for the driver's measurement-cycle action to appear
ACTIONS = ("~/rotation_sweep", "mows/mapper/rotation_sweep")  # the node's own, the previous release's


class MapperNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        self._runner = SweepRunner()
        self._settings = SweepSettings()  # the running sweep's
        self._driver = DriverCycles(self, self._on_fit)
        probes = probe_set(self._param("probes"), probe_of(self._param("probe_file")))
        self._sweep_pub = self.create_publisher(SweepDecomposition, "mows/sweep", maps_qos(max(1, len(probes))))
        self._report_pub = self.create_publisher(ModelReport, "mows/model_report", MAP_QOS)
        self._field_map_pub = self.create_publisher(FieldMap, "mows/field_map", MAP_QOS)
        self._servers = action_servers(self, RotationSweep, ACTIONS, self._execute, self._cancel, self._driver.group)
        self._operator = OperatorTurns(self, "~/confirm_orientation", lambda: self._runner.turn_awaited)

    def _param(self, name):
        return self.get_parameter(name).value

    # --- inputs ---------------------------------------------------------------------------
    def _on_fit(self, msg: RingdownFit) -> SweepStep | None:
        return self._runner.on_fit(sweep_fit(msg))

    def _refusal(self, goal: RotationSweep.Goal) -> str | None:
        """Why ``goal`` is refused, or None when the sweep starts (the runner is busy from here)."""
        if (inactive := self.inactive_reason()) is not None:
            return inactive
        try:
            probe = probe_of(self._param("probe_file"))
            self._settings = sweep_settings(parameter_values(self, PARAMETERS), probe)
            self._runner.start(sweep_goal(goal), self._settings, probe)
        except ValueError as refused:
            return str(refused)
        return None

    def _cancel(self, _) -> CancelResponse:
        self._runner.cancel()
        self._driver.cancel()
        return CancelResponse.ACCEPT

    # --- the sweep ------------------------------------------------------------------------
    async def _execute(self, goal_handle):
        if (refusal := self._refusal(goal_handle.request)) is not None:
            message = f"sweep goal refused: {refusal}"
            self.get_logger().warn(message)
            goal_handle.abort()
            return RotationSweep.Result(success=False, message=message, decomposition=no_decomposition_msg(message))
        self.get_logger().info("sweep goal accepted")
        try:
            step = self._runner.begin()
            while step.finished is None:
                if step.feedback is not None:
                    goal_handle.publish_feedback(feedback_msg(step.feedback))
                if step.turn is not None:
                    goal_handle.publish_feedback(turn_feedback_msg(step.turn))
                step = await self._advance(step)
            outcome = step.finished
            decomposition = outcome_decomposition_msg(outcome, self._param("frame_id"))
            if step.publish is not None:
                await self._publish(step.publish, decomposition)
            if step.publish_probes:
                self._publish_probes(step)
        finally:  # an exception must not leave the runner busy for good
            self._runner.abandon("the sweep ended unexpectedly (see the log)")
        if outcome.cancelled:
            goal_handle.canceled()
        elif outcome.ok:
            goal_handle.succeed()
        else:
            self.get_logger().warn(f"sweep aborted: {outcome.message}")
            goal_handle.abort()
        return RotationSweep.Result(success=outcome.ok, message=outcome.message, decomposition=decomposition)

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
        """The operator's confirmation (or a cancel) goes on with the sweep; silence ends it."""
        timeout_s = self._param("confirm_timeout_s")
        if await self._operator.confirmed(timeout_s, self._runner.cancelled):
            return self._runner.on_turned()
        return self._runner.turn_timed_out(timeout_s)

    async def _run_cycle(self, cycle: CycleRequest) -> CycleAnswer:
        if not await until(self, self._driver.ready, SERVICE_WAIT_S):
            return CycleAnswer(problem="the driver's measurement_cycle action is not available")
        answer = await self._driver.run(cycle, self._param("cycle_timeout_s"))
        return dataclasses.replace(answer, problem=f"cycle failed: {answer.problem}") if answer.problem else answer

    async def _publish(self, sweep: SweepMap, msg: SweepDecomposition) -> None:
        """A good decomposition on /mows/sweep, then the model lab's report on it."""
        self._sweep_pub.publish(msg)
        self.get_logger().info(f"sweep {sweep.sweep_id}: {self._runner.last}")
        reference = self._param("reference_scenario")
        if reference:
            probe = probe_of(self._param("probe_file"))
            try:
                table = from_sweep(sweep.record, reference, probe, sweep.decomposition)
                report = await in_worker(self, analyse, table, probe, auto=self._param("lab_auto"))
            except ValueError as error:  # a table the lab cannot use is reported, not fatal
                self.get_logger().warn(f"model lab: {error}")
            else:
                self._report_pub.publish(model_report_msg(report, msg.header, sweep.sweep_id))

    def _publish_probes(self, step: SweepStep) -> None:
        """Each probe's decomposition on /mows/sweep, then the field map of them all."""
        frame_id = self._param("frame_id")
        messages = [probe_decomposition_msg(sweep, frame_id) for sweep in step.publish_probes]
        for msg in messages:
            self._sweep_pub.publish(msg)
        self._field_map_pub.publish(field_map_msg(messages, self._settings.probes, frame_id))
        self.get_logger().info(f"sweep of {len(messages)} probes: {self._runner.last}")

    def health(self) -> Health:
        failure = self._runner.last_failure
        values = {"state": self._runner.state, "sweeps": self._runner.sweeps, "last_failure": failure}
        if failure:
            return Health(DiagnosticStatus.WARN, f"the last sweep failed: {failure}", values)
        return Health(DiagnosticStatus.OK, self._runner.last, values)


def main(args: list[str] | None = None) -> int:
    return run_node(MapperNode, args)
