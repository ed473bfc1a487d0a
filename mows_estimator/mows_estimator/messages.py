"""Translation between mows_msgs and the dataclasses of ``mows`` (no logic of its own)."""

import math

import numpy as np
from mows_msgs.msg import FieldEstimate, RingdownFit
from sensor_msgs.msg import MagneticField

from mows.estimate.axis import AxisEstimate
from mows.estimate.segments import RingdownWindow
from mows.estimate.stream import Estimated
from mows.records import stamps


def fit_to_msg(estimated: Estimated, frame_id: str) -> RingdownFit:
    """The fit of a ring-down, with the frequency shift of its estimate."""
    fit, window = estimated.fit, estimated.window
    msg = RingdownFit()
    stamps.set_nanoseconds(msg.header.stamp, estimated.stamp_ns)
    msg.header.frame_id = frame_id
    msg.cycle_id, msg.repeat_index, msg.tuning = window.cycle_id, window.repeat_index, window.tuning
    msg.status, msg.status_name, msg.message = int(fit.status), fit.status.name, fit.message
    msg.probe_id = fit.probe_id
    msg.theta0_rad, msg.theta0_free = fit.theta0_rad, fit.theta0_free
    for name in (
        "frequency_hz",
        "frequency_std_hz",
        "frequency_crb_hz",
        "damping_per_s",
        "amplitude_rad",
        "rest_offset_rad",
        "phase_rad",
        "kappa_t",
        "offset_t",
        "chi2_dof",
        "r_squared",
        "snr_db",
        "duration_s",
        "start_offset_s",
    ):
        setattr(msg, name, float(getattr(fit, name)))
    shift = estimated.estimate
    msg.frequency_shift_hz, msg.frequency_shift_std_hz = (
        float(shift.frequency_shift_hz),
        float(shift.frequency_shift_std_hz),
    )
    msg.n_samples = int(fit.n_samples)
    msg.parameter_names = list(fit.parameter_names)
    msg.covariance = np.asarray(fit.covariance, dtype=float).ravel().tolist()
    pickup = np.asarray(fit.pickup, complex)
    msg.pickup_real, msg.pickup_imag = pickup.real.tolist(), pickup.imag.tolist()
    return msg


def estimate_to_msg(estimate: AxisEstimate, header, window: RingdownWindow) -> FieldEstimate:
    msg = FieldEstimate(header=header, cycle_id=window.cycle_id, repeat_index=window.repeat_index)
    msg.status, msg.message = int(estimate.status), estimate.message
    for name in (
        "theta0_rad",
        "frequency_shift_hz",
        "frequency_shift_std_hz",
        "field_along_axis_t",
        "field_along_axis_std_t",
        "gradient_equivalent_t_per_m",
        "gradient_equivalent_std_t_per_m",
    ):
        setattr(msg, name, float(getattr(estimate, name)))
    msg.assumptions = estimate.assumptions
    return msg


def magnetic_field_msg(estimate: AxisEstimate, header) -> MagneticField:
    """REP-145: tesla, in the probe frame; only x' is measured, y' and z' are NaN. The
    covariance holds the variance of x' and zeros (unknown) elsewhere."""
    msg = MagneticField(header=header)
    msg.magnetic_field.x = estimate.field_along_axis_t
    msg.magnetic_field.y = math.nan
    msg.magnetic_field.z = math.nan
    covariance = [0.0] * 9
    covariance[0] = estimate.field_along_axis_std_t**2
    msg.magnetic_field_covariance = covariance
    return msg
