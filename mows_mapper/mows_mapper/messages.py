"""Translation between mows_msgs and the sweep runner's dataclasses (no logic of its own)."""

from mows_msgs.action import RotationSweep
from mows_msgs.msg import CandidateEffect, FieldMap, ModelReport, ProbeField, SweepDecomposition

from mows.estimate.probe_set import ProbeEntry, probe_frame_id
from mows.records import stamps
from mows.sweep.decomposition import DecompositionStatus
from mows.sweep.events import SweepFeedback, SweepGoal, SweepMap, SweepOutcome, SweepStep
from mows.sweep.operator import turn_prompt
from mows.sweep.publication import Publication

# What a probe's point of the field map takes from its SweepDecomposition, as it is there.
PROBE_FIELD_FROM_SWEEP = (
    "probe_id",
    "sweep_id",
    "status",
    "message",
    "model",
    "field_t",
    "field_covariance_t2",
    "gradient_t_per_m",
    "gradient_covariance",
)


def sweep_goal(goal: RotationSweep.Goal) -> SweepGoal:
    """ValueError for a target the goal cannot have (:meth:`SweepGoal.asked`)."""
    return SweepGoal.asked(
        goal.theta0_rad,
        goal.repeats_per_angle,
        goal.model,
        goal.target,
        goal.target_field_std_t,
        goal.target_gradient_std_t_per_m,
        goal.budget_s,
    )


def feedback_msg(feedback: SweepFeedback) -> RotationSweep.Feedback:
    return RotationSweep.Feedback(
        angle_index=feedback.angle_index,
        n_angles=feedback.n_angles,
        theta0_rad=float(feedback.theta0_rad),
        frequency_shift_hz=feedback.shift_hz,
        frequency_shift_std_hz=feedback.shift_std_hz,
        n_ok=feedback.n_ok,
        fits=list(feedback.fits),
    )


def step_feedback_msgs(step: SweepStep) -> list[RotationSweep.Feedback]:
    """The feedback a sweep's ``step`` gives, in order: an orientation done, then a turn to ask for."""
    done = [] if step.feedback is None else [feedback_msg(step.feedback)]
    return done + ([] if step.turn is None else [turn_feedback_msg(step.turn)])


def turn_feedback_msg(theta0_rad: float) -> RotationSweep.Feedback:
    """The operator's prompt before the cycle at ``theta0_rad`` (no shift measured yet: NaN)."""
    nan = float("nan")
    return RotationSweep.Feedback(
        theta0_rad=float(theta0_rad),
        frequency_shift_hz=nan,
        frequency_shift_std_hz=nan,
        operator_prompt=turn_prompt(theta0_rad),
    )


def decomposition_msg(sweep: SweepMap, frame_id: str) -> SweepDecomposition:
    d, record = sweep.decomposition, sweep.record
    msg = SweepDecomposition(sweep_id=sweep.sweep_id, model=d.model, message=d.message, status=int(d.status))
    msg.probe_id, msg.cycle_ids = sweep.probe_id, list(sweep.cycle_ids)
    msg.header.frame_id = frame_id
    # A probe of a multi-probe sweep may have no ring-down at all: its stamp is then unknown (0).
    stamps.set_nanoseconds(msg.header.stamp, max((p.stamp_ns for p in record.points), default=0))
    msg.field_t = d.field_t.tolist()
    msg.field_covariance_t2 = d.field_covariance_t2.ravel().tolist()
    msg.gradient_t_per_m = d.gradient_t_per_m.tolist()
    msg.gradient_covariance = d.gradient_covariance.ravel().tolist()
    msg.f00_hz, msg.f00_free = d.f00_hz if d.ok else sweep.f00_hz, d.f00_free
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


def sweep_frame_id(sweep: SweepMap, frame_id: str, per_probe: bool) -> str:
    """The frame of a probe's decomposition: its own rotation-plane frame when the probes are
    listed (``per_probe``), else the single probe's ``frame_id``."""
    return probe_frame_id(frame_id, sweep.probe_id, per_probe)


def publication_msgs(plan: Publication, frame_id: str) -> list[SweepDecomposition]:
    """The SweepDecomposition of each sweep ``plan`` publishes, in its probe's frame when it says so."""
    return [decomposition_msg(sweep, sweep_frame_id(sweep, frame_id, plan.per_probe)) for sweep in plan.sweeps]


def field_map_msg(decompositions: list[SweepDecomposition], probes: tuple[ProbeEntry, ...], frame_id: str) -> FieldMap:
    """The field map of a multi-probe sweep: each probe's decomposition at its position in the
    stage's rotation-plane frame ``frame_id``; stamped with the latest ring-down."""
    msg = FieldMap()
    msg.header.frame_id = frame_id
    msg.header.stamp = max(decompositions, key=lambda d: stamps.nanoseconds(d.header.stamp)).header.stamp
    for d, entry in zip(decompositions, probes):
        point = ProbeField(frame_id=d.header.frame_id, position_m=[float(x) for x in entry.position_m])
        for name in PROBE_FIELD_FROM_SWEEP:
            setattr(point, name, getattr(d, name))
        msg.probes.append(point)
    return msg


def no_decomposition_msg(message: str) -> SweepDecomposition:
    """A sweep that came to no decomposition, with why."""
    return SweepDecomposition(status=int(DecompositionStatus.NO_DECOMPOSITION), message=message)


def outcome_decomposition_msg(outcome: SweepOutcome, frame_id: str, per_probe: bool) -> SweepDecomposition:
    """The decomposition of a finished sweep (the first probe's), in its probe's frame when
    ``per_probe``; NO_DECOMPOSITION, with why, if it had none."""
    if outcome.map is None:
        return no_decomposition_msg(outcome.message)
    return decomposition_msg(outcome.map, sweep_frame_id(outcome.map, frame_id, per_probe))


def refused_result(message: str) -> RotationSweep.Result:
    """The result of a sweep goal refused on arrival, with why."""
    return RotationSweep.Result(success=False, message=message, decomposition=no_decomposition_msg(message))


def result_msg(outcome: SweepOutcome, frame_id: str, per_probe: bool) -> RotationSweep.Result:
    """The result of a finished sweep, with its decomposition (:func:`outcome_decomposition_msg`)."""
    decomposition = outcome_decomposition_msg(outcome, frame_id, per_probe)
    return RotationSweep.Result(success=outcome.ok, message=outcome.message, decomposition=decomposition)


def model_report_msg(report, header, sweep_id: int) -> ModelReport:
    return ModelReport(
        header=header,
        sweep_id=sweep_id,
        model=report.model,
        effects=list(report.effects),
        n=report.n,
        chi2_dof=report.chi2_dof,
        bic=report.bic,
        cv_rms_hz=report.cv_rms_hz,
        verdict=report.verdict,
        structure=report.structure,
        candidates=[
            CandidateEffect(
                effect=c.label,
                explanation=c.effect.explanation,
                delta_bic=c.delta_bic,
                p_value=c.p_value,
                chi2_dof_after=c.chi2_dof_after,
                parameter_names=[p.name for p in c.parameters],
                parameter_values=[p.value for p in c.parameters],
                parameter_std=[p.std for p in c.parameters],
                parameter_units=[p.unit for p in c.parameters],
                group=c.group,
            )
            for c in report.candidates
        ],
    )
