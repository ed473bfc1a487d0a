"""Translation between mows_msgs and the calibration's dataclasses (no logic of its own)."""

import dataclasses
import math

from mows_msgs.action import CalibrateProbe
from mows_msgs.msg import RingdownFit

from mows.estimate.calibration.constants import ProbeCalibration
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitStatus
from mows.estimate.ringdown import RingdownFit as Fit
from mows.sweep.calibration.schedule import CalibrationOutcome, Feedback

FIT_FIELDS = (
    "message",
    "theta0_rad",
    "frequency_hz",
    "frequency_std_hz",
    "damping_per_s",
    "amplitude_rad",
    "rest_offset_rad",
    "duration_s",
)  # what the schedule and the calibration read of a fit


def fit_of(msg: RingdownFit) -> Fit:
    """The estimator's fit as the core's result; ValueError for a status the core does not know."""
    return Fit(status=FitStatus(msg.status), start_offset_s=COIL_OFF_SKIP_S, **{n: getattr(msg, n) for n in FIT_FIELDS})


def feedback_msg(feedback: Feedback) -> CalibrateProbe.Feedback:
    return CalibrateProbe.Feedback(**dataclasses.asdict(feedback))


def supply_answer(response) -> tuple[bool, str]:
    """A SetFieldCurrent response (None: none came) as the schedule's ``on_supply`` arguments."""
    if response is None:
        return False, "no answer from the driver's set_field_current"
    return response.success, response.message


def supply_range(response) -> tuple[float, float]:
    """The supply's range (A) a SetFieldCurrent response states; NaN … NaN when none came."""
    return (math.nan, math.nan) if response is None else (response.min_current_a, response.max_current_a)


def result_msg(outcome: CalibrationOutcome, others: int = 0) -> CalibrateProbe.Result:
    """The result of a goal that wrote no probe file (yet); ``others``: the fits of other probes
    it left out, said in the message when there were any."""
    message = outcome.message + (f"; {others} ring-down fits of other probes ignored" if others else "")
    return CalibrateProbe.Result(success=False, message=message, supply_at_zero=outcome.supply_at_zero)


def calibrated(result: CalibrateProbe.Result, calibration: ProbeCalibration, path: str) -> CalibrateProbe.Result:
    """``result`` of a goal whose calibration was written to ``path``."""
    result.success, result.message, result.probe_file = True, f"{result.message}; probe file {path}", path
    result.names = list(calibration.names)
    result.values = [float(v) for v in calibration.values]
    result.stds = [calibration.std(n) for n in calibration.names]
    return result
