"""The estimator's parameter table; the fit settings of its values are the core's
(:class:`mows.estimate.settings.FitParameters`)."""

import array
import math

from mows.estimate.settings import FitParameters
from mows_ros.params import ParamSpec
from mows_ros.probe import PROBE_FILE, PROBES

DEFAULT = FitParameters()  # the defaults of the parameters of its fields


def _direction_problem(value) -> str | None:
    """Why ``value`` is no sensor_direction, or None."""
    numbers = list(value) if isinstance(value, (list, tuple, array.array)) else []
    if len(numbers) != 3 or not all(isinstance(x, float) and math.isfinite(x) for x in numbers):
        return f"sensor_direction = {list(value) if numbers else value!r} is not three finite numbers"
    if not any(numbers):
        return "sensor_direction = [0, 0, 0] has no direction"
    return None


PARAMETERS = (
    PROBE_FILE,
    ParamSpec(
        "f00_hz",
        DEFAULT.f00_hz,
        "calibrated zero-field frequency f00, Hz; 0: the probe file's f00",
        range=(0.0, 10_000.0),
    ),
    ParamSpec("f00_std_hz", DEFAULT.f00_std_hz, "standard uncertainty of f00, Hz", range=(0.0, 10.0)),
    ParamSpec(
        "channels",
        DEFAULT.channels,
        "what to fit: the sensor difference, both, or one channel",
        choices=("difference", "both", "channel1", "channel2"),
    ),
    ParamSpec(
        "sensor_axis_a",
        DEFAULT.sensor_axis_a,
        "sensing axis (a, b) in the rotation plane, Eq. S11 (paper: 0, 1)",
        range=(-1.0, 1.0),
    ),
    ParamSpec("sensor_axis_b", DEFAULT.sensor_axis_b, "see sensor_axis_a", range=(-1.0, 1.0)),
    ParamSpec(
        "theta0_free",
        DEFAULT.theta0_free,
        "fit θ0 instead of taking the commanded orientation (paper's signal model only)",
    ),
    ParamSpec(
        "lever_aware",
        DEFAULT.lever_aware,
        "fit the exact pickup of the magnet swinging on its lever "
        "(mows.physics.fluxgate.pickup_harmonics) instead of Eq. S11's magnet turning in place",
    ),
    ParamSpec(
        "sensor_distance_m",
        DEFAULT.sensor_distance_m,
        "distance from the probe to the near fluxgate, along sensor_direction, m",
        range=(0.005, 2.0),
    ),
    ParamSpec(
        "sensor_direction",
        list(DEFAULT.sensor_direction),
        "the line from the probe through both fluxgates, in the rotation plane's frame (x = e1, y = e2, "
        "z their normal; the paper: [1, 0, 0]); any length but zero",
        check=_direction_problem,
    ),
    ParamSpec("sensor_spacing_m", DEFAULT.sensor_spacing_m, "spacing of the two fluxgates, m", range=(0.001, 2.0)),
    ParamSpec(
        "coil_off_skip_s",
        DEFAULT.coil_off_skip_s,
        "samples right after coil-off that are skipped, s",
        range=(0.0, 0.1),
        formerly=("settle_s",),
    ),
    ParamSpec("min_periods", DEFAULT.min_periods, "shortest usable ring-down, in periods", range=(2.0, 1000.0)),
    ParamSpec("max_chi2_dof", DEFAULT.max_chi2_dof, "above this χ²/dof a fit is refused (BAD_FIT)", range=(1.0, 1e6)),
    ParamSpec("buffer_s", 5.0, "seconds of raw samples kept to assemble ring-downs", range=(0.5, 60.0), read_only=True),
    ParamSpec("fit_tuning_ringdowns", False, "also fit the driver's frequency-tuning ring-downs"),
    ParamSpec("probe_frame_id", "mows_probe", "frame of the probe (x' along the moment at rest)"),
    PROBES,
)
