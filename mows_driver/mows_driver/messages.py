"""Translation of the device session's blocks and phase events into mows_msgs (no logic)."""

import array

from mows_msgs.msg import ExcitationState, MagnetometerBlock, MagnetometerChannel, SupplyState
from mows_msgs.srv import EmergencyStop, RunCycle, SetFieldCurrent
from sensor_msgs.msg import JointState

from mows.device.cycle.phases import CycleOutcome, CycleRequest, PhaseEvent, SupplyEvent
from mows.device.interface import CommandResult
from mows.device.protocol.payloads import DeviceInfo
from mows.records import stamps


def block_msg(block, info: DeviceInfo, frame_id: str, sensor_frame_ids: list) -> MagnetometerBlock:
    """One block of samples; channel i is in ``sensor_frame_ids[i]`` (``channel_<i+1>`` past them)."""
    message = MagnetometerBlock(
        sequence=block.sequence,
        device_epoch=block.epoch,
        first_sample_index=block.first_sample_index,
        sample_rate_hz=info.sample_rate_hz,
        range_t=info.range_t,
        resolution_t=info.resolution_t,
    )
    stamps.set_nanoseconds(message.header.stamp, block.stamp_ns)
    message.header.frame_id = frame_id
    message.channels = [
        MagnetometerChannel(
            frame_id=sensor_frame_ids[i] if i < len(sensor_frame_ids) else f"channel_{i + 1}",
            field_t=array.array("d", block.samples_t[:, i].tobytes()),
            saturated=block.saturated[:, i].tolist(),
        )
        for i in range(block.samples_t.shape[1])
    ]
    return message


STAGE_JOINT = "mows_stage"  # the rotation stage's joint in mows_bringup/urdf/mows_probe_mount.urdf


def joint_state_msg(stamp_ns: int, stage_angle_rad: float) -> JointState:
    """The rotation stage at θ0 (rad, from the plane's x towards y) at a device stamp."""
    message = JointState(name=[STAGE_JOINT], position=[float(stage_angle_rad)])
    stamps.set_nanoseconds(message.header.stamp, stamp_ns)
    return message


EVENT_FIELDS = (
    "cycle_id",
    "repeat_index",
    "repeats",
    "tuning",
    "coils_on",
    "frequency_hz",
    "theta0_rad",
    "planned_duration_s",
    "setup",
    "probe_ids",
    "probe_frequency_hz",
    "probe_theta0_rad",
)  # a PhaseEvent's fields that ExcitationState carries under the same name


def excitation_msg(event: PhaseEvent, frame_id: str, device_epoch: int = 0) -> ExcitationState:
    """A phase change, stamped on the device clock of ``device_epoch``."""
    message = ExcitationState(
        device_epoch=device_epoch,
        phase=int(event.phase),
        phase_name=event.phase.name,
        coil_current_amplitude_a=list(event.currents_a),
        **{
            name: list(getattr(event, name)) if name.startswith("probe_") else getattr(event, name)
            for name in EVENT_FIELDS
        },
    )
    stamps.set_nanoseconds(message.header.stamp, event.stamp_ns)
    message.header.frame_id = frame_id
    return message


def supply_msg(event: SupplyEvent, frame_id: str) -> SupplyState:
    message = SupplyState(
        current_a=float(event.current_a), ramping=event.ramping, sample_index=event.sample_index, reason=event.reason
    )
    stamps.set_nanoseconds(message.header.stamp, event.stamp_ns)
    message.header.frame_id = frame_id
    return message


def cycle_request(request: RunCycle.Request) -> CycleRequest:
    """A RunCycle request (or MeasurementCycle goal); a negative repeats, tuning_steps or gap_s
    takes the parameter."""
    return CycleRequest(
        request.theta0_rad,
        request.repeats if request.repeats >= 0 else None,
        request.tuning_steps if request.tuning_steps >= 0 else None,
        request.gap_s if request.gap_s >= 0.0 else None,
        turned_by_hand=request.turned_by_hand,
    )


def cycle_response(outcome: CycleOutcome, response):
    """A RunCycle response or MeasurementCycle result (the same fields) of ``outcome``."""
    response.success, response.message, response.cycle_id = outcome.success, outcome.message, outcome.cycle_id
    response.excitation_frequency_hz = outcome.frequency_hz
    response.ringdowns_recorded = outcome.ringdowns_recorded
    return response


def estop_response(
    latched: bool, request: EmergencyStop.Request, response: EmergencyStop.Response, backend: str
) -> EmergencyStop.Response:
    """``latched``: the latch after the request; it failed if that is not what was asked."""
    response.latched, response.success = latched, latched == request.engage
    response.message = (
        ("coils off, latched" if latched else "released")
        if response.success
        else f"the {backend} backend has no coils to stop"
    )
    return response


def estop_unlinked_response(lifecycle_state: str, response: EmergencyStop.Response) -> EmergencyStop.Response:
    """The answer to an emergency stop while there is no device link: nothing is on to stop."""
    response.success, response.latched = False, False
    response.message = f"the driver is {lifecycle_state}: no device link, nothing it drives is on"
    return response


def supply_response(result: CommandResult, current_a: float, response: SetFieldCurrent.Response) -> None:
    """The answer to set_field_current: reached (at which sample) or refused by the device."""
    response.success = result.accepted
    response.message = (
        f"supply at {current_a:+.4f} A from device sample {result.applied_sample_index}"
        if result.accepted
        else f"the device refused the supply current: {result.reason}"
    )
    response.current_a = round(float(current_a), 4) if result.accepted else float("nan")
    response.reached_sample_index = max(0, result.applied_sample_index)


def supply_range(limits, cap_a: float, response: SetFieldCurrent.Response) -> None:
    """The supply's range in ``response`` under the driver's ``cap_a`` (``limits``:
    SupplyLimits); NaN for a supply the backend does not know."""
    nan = float("nan")
    response.min_current_a, response.max_current_a = (nan, nan) if limits is None else limits.range_a(cap_a)
