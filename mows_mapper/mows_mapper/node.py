"""The mapper node: rotation sweeps, their field/gradient decomposition, and the model lab.

Names are relative (here as in the root namespace). Action ``/mows/mapper/rotation_sweep``
(RotationSweep): for each orientation it asks the
driver for one measurement cycle (``/mows/driver/run_cycle``), collects that cycle's
ring-down fits from the estimator (``/mows/ringdown``), reports them as feedback, and at the
end decomposes the sweep (``mows.sweep.decompose``) into in-plane field and gradient. The result is
published on ``/mows/sweep`` (SweepDecomposition, reliable and transient-local: a map). With a
reference (``reference_scenario``) the model lab (``mows.lab.analyse``) compares the
frequency model with the sweep and publishes ``/mows/model_report`` (ModelReport).
"""
import collections
import math
import threading
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticStatus
from mows_msgs.action import RotationSweep
from mows_msgs.msg import CandidateEffect, ModelReport, RingdownFit, SweepDecomposition
from mows_msgs.srv import RunCycle
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup

from mows.lab import analyse, from_sweep, reference_at
from mows.physics.probe import Probe
from mows.records import stamps
from mows.sweep.decompose import MODELS
from mows.sweep.record import SweepPoint, SweepRecord
from mows_ros.diagnostics import Health
from mows_ros.node import MowsNode
from mows_ros.params import ParamSpec
from mows_ros.probe import PROBE_FILE, probe_of
from mows_ros.process import run_node
from mows_ros.qos import MAP_QOS, RESULT_QOS

NODE_NAME = "mapper"


def reference_problem(name: str) -> str | None:
    """Why ``reference_scenario`` cannot serve as the lab's reference, or None."""
    try:
        if name:
            reference_at(name)
    except (OSError, ValueError, KeyError, TypeError) as error:
        return f"reference_scenario={name!r}: {error}"
    return None


PARAMETERS = (
    ParamSpec("repeats_per_angle", 5, "ring-downs per orientation when the goal says 0", range=(1, 100)),
    ParamSpec("angle_step_deg", 30.0, "orientation step when the goal lists no angles, deg", range=(1.0, 180.0)),
    ParamSpec("model", "first_principles", "decomposition model when the goal names none", choices=MODELS),
    ParamSpec("f00_free", False, "fit the zero-field frequency in the decomposition (Gs is then undetermined)"),
    PROBE_FILE,
    ParamSpec("cycle_timeout_s", 300.0, "longest wait for the driver's cycle, s", range=(1.0, 3600.0)),
    ParamSpec("fit_timeout_s", 10.0, "longest wait for the fits of a finished cycle, s", range=(0.1, 600.0)),
    ParamSpec("reference_scenario", "", "scenario whose field at the probe is the lab's reference "
              "(shipped name or YAML); empty: no model report", check=reference_problem),
    ParamSpec("lab_auto", True, "let the lab add effects while the evidence is strong"),
    ParamSpec("frame_id", "mows_rotation_plane", "frame of the sweep: x = e1, y = e2 of the rotation plane"),
)


class MapperNode(MowsNode):
    def __init__(self):
        super().__init__(NODE_NAME, PARAMETERS)
        group = ReentrantCallbackGroup()
        self._fits = collections.defaultdict(list)   # by cycle id, while a sweep runs
        self._arrived = threading.Condition()        # guards _fits and _state
        self._sweeps = 0
        self._state = "idle"
        self._last = "no sweep yet"
        self.create_subscription(RingdownFit, "mows/ringdown", self._on_fit, RESULT_QOS, callback_group=group)
        self._cycle = self.create_client(RunCycle, "mows/driver/run_cycle", callback_group=group)
        self._sweep_pub = self.create_publisher(SweepDecomposition, "mows/sweep", MAP_QOS)
        self._report_pub = self.create_publisher(ModelReport, "mows/model_report", MAP_QOS)
        self._server = ActionServer(self, RotationSweep, "mows/mapper/rotation_sweep", self._execute,
                                    goal_callback=self._accept, cancel_callback=lambda _: CancelResponse.ACCEPT,
                                    callback_group=group)

    def _param(self, name):
        return self.get_parameter(name).value

    def probe(self) -> Probe:
        return probe_of(self._param("probe_file"))

    # --- inputs ---------------------------------------------------------------------------
    def _on_fit(self, msg: RingdownFit):
        with self._arrived:
            # Fits of cycles run by others between sweeps, and tuning ring-downs, are not ours.
            if self._state == "sweeping" and not msg.tuning:
                self._fits[msg.cycle_id].append(msg)
                self._arrived.notify_all()

    def _accept(self, goal) -> GoalResponse:
        bad = [a for a in goal.theta0_rad if not math.isfinite(a)]
        with self._arrived:     # one sweep at a time: the state changes here, not when it starts
            busy = self._state != "idle"
            if not (bad or (goal.model and goal.model not in MODELS) or busy):
                self._state = "sweeping"
                self._fits.clear()
                return GoalResponse.ACCEPT
        self.get_logger().warn(f"sweep goal refused: angles {list(goal.theta0_rad)}, model {goal.model!r}, "
                               f"state {self._state}")
        return GoalResponse.REJECT

    # --- the sweep ------------------------------------------------------------------------
    def _execute(self, goal_handle):
        goal = goal_handle.request
        angles = list(goal.theta0_rad) or list(np.radians(np.arange(0.0, 360.0, self._param("angle_step_deg"))))
        repeats = goal.repeats_per_angle or self._param("repeats_per_angle")
        model = goal.model or self._param("model")
        record, f00_seen = SweepRecord(), []
        try:
            for index, theta0 in enumerate(angles):
                if goal_handle.is_cancel_requested:
                    goal_handle.canceled()
                    return self._result(False, f"cancelled after {index} of {len(angles)} orientations")
                fits, problem = self._measure(theta0, repeats)
                if problem:
                    goal_handle.abort()
                    return self._result(False, f"orientation {index} ({math.degrees(theta0):.1f}°): {problem}")
                for fit in fits:
                    self._collect(record, fit, f00_seen)
                goal_handle.publish_feedback(self._feedback(index, len(angles), theta0, fits, record))
            return self._finish(goal_handle, record, model, f00_seen)
        finally:
            with self._arrived:
                self._state = "idle"
                self._fits.clear()

    def _measure(self, theta0: float, repeats: int):
        """One driver cycle at θ0 and its fits; (fits, '') or ([], what went wrong)."""
        if not self._cycle.wait_for_service(timeout_sec=5.0):
            return [], "the driver's run_cycle service is not available"
        request = RunCycle.Request(theta0_rad=float(theta0), repeats=int(repeats), tuning_steps=-1, gap_s=-1.0)
        response = self._call(request, self._param("cycle_timeout_s"))
        if response is None or not response.success:
            return [], f"cycle failed: {response.message if response else 'no answer from the driver'}"
        deadline = time.monotonic() + self._param("fit_timeout_s")
        with self._arrived:
            while len(self._fits[response.cycle_id]) < response.ringdowns_recorded and time.monotonic() < deadline:
                self._arrived.wait(timeout=0.1)
            return self._fits.pop(response.cycle_id, []), ""

    def _call(self, request, timeout_s: float):
        done = threading.Event()
        future = self._cycle.call_async(request)
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout_s):
            future.cancel()
            return None
        return future.result()

    @staticmethod
    def _collect(record: SweepRecord, fit: RingdownFit, f00_seen: list):
        if fit.status != RingdownFit.STATUS_OK:
            record.failed += 1
            return
        f00_seen.append(fit.frequency_hz - fit.frequency_shift_hz)   # the estimator's calibrated f00
        record.add(sweep_point(fit))

    @staticmethod
    def _feedback(index, count, theta0, fits, record) -> RotationSweep.Feedback:
        shift, std, n_ok = record.at_angle(theta0)
        return RotationSweep.Feedback(angle_index=index, n_angles=count, theta0_rad=float(theta0),
                                      frequency_shift_hz=shift, frequency_shift_std_hz=std, n_ok=n_ok, fits=fits)

    def _finish(self, goal_handle, record: SweepRecord, model: str, f00_seen: list):
        self._sweeps += 1
        if not record.points:
            goal_handle.abort()
            return self._result(False, f"no successful ring-down in the sweep ({record.failed} failed)")
        f00 = float(np.mean(f00_seen))
        decomposition = record.decompose(self.probe(), f00, model=model, f00_free=self._param("f00_free"))
        msg = self._decomposition_msg(decomposition, record, f00)
        self._sweep_pub.publish(msg)
        self._last = decomposition.report()
        self.get_logger().info(f"sweep {self._sweeps}: {self._last}")
        self._publish_model_report(record, msg.header, decomposition)
        if decomposition.ok:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return self._result(decomposition.ok, decomposition.message or self._last, msg)

    def _decomposition_msg(self, d, record: SweepRecord, f00: float) -> SweepDecomposition:
        msg = SweepDecomposition(sweep_id=self._sweeps, model=d.model, status=int(d.status), message=d.message)
        msg.header.frame_id = self._param("frame_id")
        latest = max(p.t_s for p in record.points)
        stamps.set_seconds(msg.header.stamp, latest)
        msg.field_t = d.field_t.tolist()
        msg.field_covariance_t2 = d.field_covariance_t2.ravel().tolist()
        msg.gradient_t_per_m = d.gradient_t_per_m.tolist()
        msg.gradient_covariance = d.gradient_covariance.ravel().tolist()
        msg.f00_hz, msg.f00_free = d.f00_hz if d.ok else f00, d.f00_free
        if d.harmonics is not None:
            msg.harmonic_amplitude_hz = d.harmonics.amplitude_hz.tolist()
            msg.harmonic_phase_rad = d.harmonics.phase_rad.tolist()
        angles = sorted({p.theta0_rad for p in record.points})
        summaries = [record.at_angle(a) for a in angles]
        msg.theta0_rad = angles
        msg.frequency_shift_hz = [s[0] for s in summaries]
        msg.frequency_shift_std_hz = [s[1] for s in summaries]
        msg.chi2_dof, msg.rms_residual_hz, msg.n_points = d.chi2_dof, d.rms_residual_hz, len(record.points)
        return msg

    def _publish_model_report(self, record: SweepRecord, header, decomposition):
        reference = self._param("reference_scenario")
        if not reference:
            return
        try:
            table = from_sweep(record, reference, self.probe(), decomposition)
            report = analyse(table, self.probe(), auto=self._param("lab_auto"))
        except ValueError as error:     # a table the lab cannot use is reported, not fatal
            self.get_logger().warn(f"model lab: {error}")
            return
        self._report_pub.publish(model_report_msg(report, header, self._sweeps))

    @staticmethod
    def _result(success: bool, message: str, decomposition=None) -> RotationSweep.Result:
        return RotationSweep.Result(success=bool(success), message=message,
                                    decomposition=decomposition or SweepDecomposition(status=1, message=message))

    def health(self) -> Health:
        return Health(DiagnosticStatus.OK, self._last, {"state": self._state, "sweeps": self._sweeps})


def sweep_point(fit: RingdownFit) -> SweepPoint:
    """A successful RingdownFit as a point of the sweep, with σ of θmax from its covariance."""
    return SweepPoint.from_fit(fit, fit.frequency_shift_hz, fit.frequency_shift_std_hz,
                               stamps.seconds(fit.header.stamp))


def model_report_msg(report, header, sweep_id: int) -> ModelReport:
    return ModelReport(
        header=header, sweep_id=sweep_id, model=report.model, effects=list(report.effects), n=report.n,
        chi2_dof=report.chi2_dof, bic=report.bic, cv_rms_hz=report.cv_rms_hz, verdict=report.verdict,
        structure=report.structure,
        candidates=[CandidateEffect(effect=c.label, explanation=c.effect.explanation, delta_bic=c.delta_bic,
                                    p_value=c.p_value, chi2_dof_after=c.chi2_dof_after,
                                    parameter_names=[p[0] for p in c.parameters],
                                    parameter_values=[p[1] for p in c.parameters],
                                    parameter_std=[p[2] for p in c.parameters],
                                    parameter_units=[p[3] for p in c.parameters], group=c.group)
                    for c in report.candidates])


def main(args: list[str] | None = None) -> int:
    return run_node(MapperNode, args, threads=4)
