"""The estimator's parameter table and the fit settings it makes of the parameters."""

import array
import functools
import math
from collections.abc import Sequence

from mows.estimate.probe_set import WindowProbe
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, ProbeLine
from mows.estimate.stream import FitSettings, JointSettings
from mows.physics.fluxgate import PAPER_DISTANCE_M, PAPER_SPACING_M, FluxgatePair
from mows.physics.probe import Probe
from mows_ros.params import ParamSpec
from mows_ros.probe import PROBE_FILE, PROBES, probe_set


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
    ParamSpec("f00_hz", 0.0, "calibrated zero-field frequency f00, Hz; 0: the probe file's f00", range=(0.0, 10_000.0)),
    ParamSpec("f00_std_hz", 0.0, "standard uncertainty of f00, Hz", range=(0.0, 10.0)),
    ParamSpec(
        "channels",
        "difference",
        "what to fit: the sensor difference, both, or one channel",
        choices=("difference", "both", "channel1", "channel2"),
    ),
    ParamSpec(
        "sensor_axis_a", 0.0, "sensing axis (a, b) in the rotation plane, Eq. S11 (paper: 0, 1)", range=(-1.0, 1.0)
    ),
    ParamSpec("sensor_axis_b", 1.0, "see sensor_axis_a", range=(-1.0, 1.0)),
    ParamSpec("theta0_free", False, "fit θ0 instead of taking the commanded orientation (paper's signal model only)"),
    ParamSpec(
        "lever_aware",
        True,
        "fit the exact pickup of the magnet swinging on its lever "
        "(mows.physics.fluxgate.pickup_harmonics) instead of Eq. S11's magnet turning in place",
    ),
    ParamSpec(
        "sensor_distance_m",
        PAPER_DISTANCE_M,
        "distance from the probe to the near fluxgate, along sensor_direction, m",
        range=(0.005, 2.0),
    ),
    ParamSpec(
        "sensor_direction",
        [1.0, 0.0, 0.0],
        "the line from the probe through both fluxgates, in the rotation plane's frame (x = e1, y = e2, "
        "z their normal; the paper: [1, 0, 0]); any length but zero",
        check=_direction_problem,
    ),
    ParamSpec("sensor_spacing_m", PAPER_SPACING_M, "spacing of the two fluxgates, m", range=(0.001, 2.0)),
    ParamSpec(
        "coil_off_skip_s",
        COIL_OFF_SKIP_S,
        "samples right after coil-off that are skipped, s",
        range=(0.0, 0.1),
        formerly=("settle_s",),
    ),
    ParamSpec("min_periods", 10.0, "shortest usable ring-down, in periods", range=(2.0, 1000.0)),
    ParamSpec("max_chi2_dof", 25.0, "above this χ²/dof a fit is refused (BAD_FIT)", range=(1.0, 1e6)),
    ParamSpec("buffer_s", 5.0, "seconds of raw samples kept to assemble ring-downs", range=(0.5, 60.0), read_only=True),
    ParamSpec("fit_tuning_ringdowns", False, "also fit the driver's frequency-tuning ring-downs"),
    ParamSpec("probe_frame_id", "mows_probe", "frame of the probe (x' along the moment at rest)"),
    PROBES,
)


def fluxgate_pair(values: dict) -> FluxgatePair:
    """The pair the parameters describe, the probe at the origin of the rotation plane's frame."""
    return FluxgatePair.paper(
        distance_m=values["sensor_distance_m"],
        spacing_m=values["sensor_spacing_m"],
        direction=values["sensor_direction"],
        axis=(values["sensor_axis_a"], values["sensor_axis_b"], 0.0),
    )


def fit_options(values: dict, probe: Probe, theta0_rad: float) -> FitOptions:
    """The ring-down fit the parameters ask for at θ0. ValueError when no model can be made
    (e.g. a sensing axis of (0, 0))."""
    direction = (values["sensor_axis_a"], values["sensor_axis_b"])
    channels = values["channels"]
    common = dict(sensor_direction=direction, min_periods=values["min_periods"], max_chi2_dof=values["max_chi2_dof"])
    if values["lever_aware"] and not values["theta0_free"] and channels != "both":
        return FitOptions.lever_aware(fluxgate_pair(values), probe, theta0_rad, channels, **common)
    return FitOptions(channels=channels, theta0_free=values["theta0_free"], **common)


def joint_lines(values: dict, held: Sequence[WindowProbe]) -> list[ProbeLine]:
    """The lines of the probes a window holds, each at its own θ0, for the joint fit the
    parameters ask for; ValueError for what it cannot do (a fitted θ0)."""
    if values["theta0_free"]:
        raise ValueError("theta0_free: the joint fit of several probes takes θ0 from the excitation")
    pair = fluxgate_pair(values) if values["lever_aware"] and values["channels"] != "both" else None
    return [p.entry.line(p.theta0_rad, pair, values["channels"], p.tone_hz) for p in held if p.entry is not None]


def joint_settings(values: dict, probe: Probe) -> JointSettings | None:
    """The joint fit of the listed probes; None when ``probes`` is empty (one probe)."""
    probes = probe_set(values["probes"], probe)
    if not probes:
        return None
    options = FitOptions(values["channels"], min_periods=values["min_periods"], max_chi2_dof=values["max_chi2_dof"])
    return JointSettings(probes, functools.partial(joint_lines, values), options)


def fit_settings(values: dict, probe: Probe) -> FitSettings:
    """What the parameters ask of each ring-down's fit and inversion; f00 = 0 is the probe's."""
    f00_hz = values["f00_hz"] if values["f00_hz"] > 0 else probe.f00_hz
    return FitSettings(
        probe,
        functools.partial(fit_options, values, probe),
        values["coil_off_skip_s"],
        f00_hz,
        values["f00_std_hz"],
        joint_settings(values, probe),
    )
