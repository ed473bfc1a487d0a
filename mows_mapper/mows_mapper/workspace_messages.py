"""The workspace map's messages: CRTK poses (geometry_msgs/PoseStamped) to and from
:class:`mows.workspace.arm.StampedPose`, a visited pose as the action's feedback, the fitted map
as ``mows_msgs/WorkspaceModel`` and the answer of ``FieldAt``."""

import numpy as np
from geometry_msgs.msg import PoseStamped
from mows_msgs.action import WorkspaceMap as WorkspaceMapAction
from mows_msgs.msg import WorkspaceModel
from mows_msgs.srv import FieldAt

from mows.records import stamps
from mows.workspace.arm import StampedPose
from mows.workspace.mapping import WorkspaceMap
from mows.workspace.runner import MapFeedback
from mows.workspace.tool import wrench
from mows_mapper.messages import outcome_decomposition_msg


def pose_stamped_msg(pose: StampedPose) -> PoseStamped:
    msg = PoseStamped()
    stamps.set_nanoseconds(msg.header.stamp, pose.stamp_ns)
    msg.header.frame_id = pose.frame_id
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (float(v) for v in pose.position_m)
    o = msg.pose.orientation
    o.x, o.y, o.z, o.w = (float(v) for v in pose.orientation_xyzw)
    return msg


def feedback_msg(feedback: MapFeedback) -> WorkspaceMapAction.Feedback:
    msg = WorkspaceMapAction.Feedback(
        sweep_index=feedback.sweep_index,
        n_sweeps=feedback.n_sweeps,
        accepted=feedback.accepted,
        refusal=feedback.refusal,
    )
    if feedback.pose is not None:
        msg.pose = pose_stamped_msg(feedback.pose)
    if feedback.outcome is not None and feedback.outcome.map is not None:
        msg.decomposition = outcome_decomposition_msg(feedback.outcome, "", False)
    return msg


def workspace_model_msg(the_map: WorkspaceMap, sweep_ids: list[int], stamp_ns: int) -> WorkspaceModel:
    model, settings = the_map.model, the_map.settings
    field_error, gradient_error = the_map.rms_std()
    msg = WorkspaceModel(
        centre_m=[float(v) for v in settings.centre_m],
        scale_m=float(model.basis.scale_m),
        radius_m=float(settings.radius_m),
        degree=int(model.basis.max_degree),
        degree_choice=the_map.choice.report(),
        coefficients_t=model.coefficients.tolist(),
        coefficient_std_t=np.sqrt(np.diag(model.covariance)).tolist(),
        covariance_t2=model.covariance.ravel().tolist(),
        chi2=float(model.chi2),
        dof=int(model.dof),
        pose_std_m=float(settings.accuracy.position_std_m),
        pose_std_rad=float(settings.accuracy.angle_std_rad),
        field_error_t=field_error,
        gradient_error_t_per_m=gradient_error,
        poses=[pose_stamped_msg(p) for p in the_map.poses],
        sweep_ids=list(sweep_ids),
    )
    msg.header.frame_id = settings.frame_id
    stamps.set_nanoseconds(msg.header.stamp, stamp_ns)
    return msg


def field_at_response(the_map: WorkspaceMap | None, request: FieldAt.Request, response: FieldAt.Response):
    """The map's B, G and the tool's force and torque at the asked point, each with σ; a
    refusal with the reason when there is no map or the point lies outside its workspace."""
    if the_map is None:
        response.success, response.message = False, "no workspace map yet: run a workspace_map goal first"
        return response
    point = np.array([[request.position.x, request.position.y, request.position.z]])
    if problem := the_map.outside_problem(point[0]):
        response.success, response.message = False, problem
        return response
    field, field_std = the_map.model.field_t(point)
    gradient, gradient_std = the_map.model.gradient_t_per_m(point)
    tool = wrench(the_map.model, point, np.asarray(request.tool_moment_am2, float))
    response.success, response.message, response.frame_id = True, "", the_map.settings.frame_id
    response.field_t, response.field_std_t = field[0].tolist(), field_std[0].tolist()
    response.gradient_t_per_m, response.gradient_std_t_per_m = (
        gradient[0].ravel().tolist(),
        gradient_std[0].ravel().tolist(),
    )
    response.force_n, response.force_std_n = tool.force_n[0].tolist(), tool.force_std_n[0].tolist()
    response.torque_nm, response.torque_std_nm = tool.torque_nm[0].tolist(), tool.torque_std_nm[0].tolist()
    return response
