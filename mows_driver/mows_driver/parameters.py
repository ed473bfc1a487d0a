"""The driver's parameter table, the checks across its parameters, and the core's settings it
makes of them: the device backend's (:class:`mows.device.backends.factory.BackendSettings`, made
once: its parameters are fixed at start-up, and its scenario is read then), the cycle's and
tracking's (planned by the device layer, :func:`mows.device.cycle.tracking_plan.tracking_settings`,
with the estimator's Cramér–Rao bound)."""

import dataclasses
import math

from mows.device.backends.factory import BackendSettings
from mows.device.cycle import tracking_plan
from mows.device.cycle.phases import CycleSettings
from mows.device.cycle.tracking import TrackingSettings
from mows.device.serial.link import DEFAULT_BAUD
from mows.device.stream.session import SessionConfig
from mows.estimate.ringdown import COIL_OFF_SKIP_S, fit_tuning
from mows.estimate.ringdown.problem import cramer_rao_frequency_hz
from mows.physics.coils import PRESETS, CurrentCap
from mows.physics.probe import PAPER_PROBE
from mows.sim.scenario import DEFAULT_SCENARIO
from mows_ros.params import ParamSpec, spec_named

PARAMETERS = (
    ParamSpec(
        "backend",
        "sim",
        "where magnetometer blocks come from: sim (the simulator), serial (the device on "
        "a serial port), bag (a recorded rosbag2 MCAP bag), nidaqmx (the paper's bench on an NI card, "
        "docs/hardware.md); fixed at start-up",
        choices=("sim", "serial", "bag", "nidaqmx"),
        read_only=True,
    ),
    ParamSpec(
        "scenario",
        DEFAULT_SCENARIO,
        "backend sim: simulator scenario, a YAML file or the name of one "
        "shipped in mows/sim/scenarios; fixed at start-up",
        read_only=True,
    ),
    ParamSpec(
        "theta0_rad",
        0.0,
        "backend sim: the stage's angle at start-up, rad (cycles turn it): each probe at its home orientation plus it",
        range=(-2.0 * math.pi, 2.0 * math.pi),
        read_only=True,
    ),
    ParamSpec(
        "serial_port", "", "backend serial: the device's port, e.g. /dev/ttyACM0; fixed at start-up", read_only=True
    ),
    ParamSpec(
        "baud",
        DEFAULT_BAUD,
        "backend serial: baud rate (ignored by USB CDC links), bit/s",
        range=(9600, 12_000_000),
        read_only=True,
    ),
    ParamSpec("bag_path", "", "backend bag: the bag directory to replay; fixed at start-up", read_only=True),
    ParamSpec("bag_rate", 1.0, "backend bag: replay speed, multiple of real time", range=(0.01, 100.0), read_only=True),
    ParamSpec(
        "bag_wait_subscribers",
        0,
        "backend bag: start the replay once /mows/raw has this many subscribers",
        range=(0, 100),
        read_only=True,
    ),
    ParamSpec(
        "daq_device_file",
        "",
        "backend nidaqmx: the card's device YAML (channels, ranges, gains); '' the paper's PCIe-6363 wiring; "
        "fixed at start-up",
        read_only=True,
    ),
    ParamSpec(
        "daq_simulated",
        False,
        "backend nidaqmx: rehearse on the simulated bench, no hardware: NI's nidaqmx package on a simulated "
        "card (the paper's largest-spacing scene, in wall-clock time) and, with supply scpi, the NGM202 on "
        "pyvisa-sim (supply_resource '' or its address); fixed at start-up",
        read_only=True,
    ),
    ParamSpec(
        "supply",
        "device",
        "the static-field supply: device (the backend's own: sim, serial), scpi (a SCPI supply through PyVISA, "
        "with backend nidaqmx), none; fixed at start-up",
        choices=("device", "scpi", "none"),
        read_only=True,
    ),
    ParamSpec(
        "supply_file",
        "",
        "supply scpi: the supply's YAML (commands, cap, slew, resolution, polarity); '' the paper's NGM202 "
        "(unipolar); fixed at start-up",
        read_only=True,
    ),
    ParamSpec(
        "supply_resource",
        "",
        "supply scpi: its VISA address, e.g. TCPIP0::192.168.0.20::inst0::INSTR; fixed at start-up",
        read_only=True,
    ),
    ParamSpec(
        "visa_library",
        "@py",
        "supply scpi: the PyVISA backend (@py: pyvisa-py, no vendor VISA); fixed at start-up",
        read_only=True,
    ),
    ParamSpec(
        "record_path",
        "",
        "write /mows/raw, /mows/excitation and /mows/supply, with the graph's fits, sweeps, maps, "
        "model reports and /diagnostics, to a new rosbag2 MCAP bag here ('' records nothing); fixed at start-up",
        read_only=True,
    ),
    ParamSpec("block_duration_s", 0.025, "length of one MagnetometerBlock on /mows/raw, s", range=(0.01, 0.05)),
    ParamSpec("frame_id", "mows_magnetometer", "header.frame_id of the blocks: the magnetometer array"),
    ParamSpec(
        "sensor_frame_ids",
        ["fluxgate_near", "fluxgate_far"],
        "frame of each channel (sensing axis = its x axis), near sensor first",
    ),
    ParamSpec("probe_frame_id", "mows_probe", "header.frame_id of the excitation states: the probe"),
    ParamSpec(
        "coil_current_cap_a",
        10.0,
        "hard limit on the peak current of any excitation coil, A; commands above it are refused; fixed at start-up",
        range=(0.01, 100.0),
        read_only=True,
    ),
    ParamSpec(
        "supply_current_cap_a",
        2.0,
        "hard limit on the static-field supply's current, A (the paper's "
        "supply: 2 A); set_field_current above it is refused; fixed at start-up",
        range=(0.001, 100.0),
        read_only=True,
    ),
    ParamSpec(
        "supply_slew_a_per_s",
        2.0,
        "backend sim: the supply's current changes no faster than this, A/s "
        "(a serial device ramps within its own limit); fixed at start-up",
        range=(0.001, 1000.0),
        read_only=True,
    ),
    ParamSpec(
        "coil_setup",
        "",
        "excitation coil setup whose orientation-dependent current scheme drives the coils ('': the "
        "scenario's); fixed at start-up",
        choices=("", *PRESETS),
        read_only=True,
    ),
    ParamSpec(
        "excitation_current_a",
        2.0,
        "base amplitude of the coil current scheme, A (at most coil_current_cap_a)",
        range=(0.0, 100.0),
    ),
    ParamSpec(
        "initial_frequency_hz",
        round(float(PAPER_PROBE.f00_hz), 1),
        "first resonance estimate, Hz (each cycle retunes it)",
        range=(1.0, 2000.0),
        read_only=True,
    ),
    ParamSpec(
        "excite_s",
        0.5,
        "coil-on time of one excitation, s (to the drive current peak nearest it)",
        range=(0.01, 10.0),
    ),
    ParamSpec("ringdown_s", 0.5, "recorded free ring-down after each excitation, s", range=(0.05, 10.0)),
    ParamSpec("gap_s", 1.0, "pause between a ring-down and the next excitation, s", range=(0.0, 600.0)),
    ParamSpec("repeats", 3, "recorded ring-downs per cycle", range=(1, 1000)),
    ParamSpec("tuning_steps", 2, "frequency-tuning excitations before the recorded ones", range=(0, 10)),
    ParamSpec("turn_settle_s", 0.5, "wait after turning the probe, s", range=(0.0, 60.0), formerly=("settle_s",)),
    ParamSpec("max_duty_cycle", 0.5, "largest share of any duty_window_s with the coils on", range=(0.01, 1.0)),
    ParamSpec("duty_window_s", 10.0, "window of the duty-cycle limit, s", range=(1.0, 3600.0)),
    ParamSpec(
        "tracking",
        False,
        "tracking mode: short kicks and ring-downs at tracking_theta0_rad back to back, lengths from the "
        "probe's physics for tracking_target_std_t, so that the estimator publishes B along the axis "
        "continuously; run_cycle is refused while it is on; an emergency stop or a failed cycle ends it",
    ),
    ParamSpec("tracking_theta0_rad", 0.0, "tracking mode: the orientation, rad", range=(-2.0 * math.pi, 2.0 * math.pi)),
    ParamSpec(
        "tracking_target_std_t",
        0.2e-6,
        "tracking mode: σ of each update of B along the axis, T (sets the ring-down length)",
        range=(1e-9, 1e-3),
    ),
    ParamSpec(
        "tracking_noise_std_t",
        0.0,
        "tracking mode: white noise σ per sample of the sensors' difference channel, T, a measured figure; "
        "0: the scenario's noise model",
        range=(0.0, 1e-6),
    ),
)
CYCLE_PARAMETERS = (
    "excitation_current_a",
    "excite_s",
    "ringdown_s",
    "gap_s",
    "repeats",
    "tuning_steps",
    "turn_settle_s",
    "max_duty_cycle",
    "duty_window_s",
)


def cycle_settings(values: dict) -> CycleSettings:
    return CycleSettings(**{name: values[name] for name in CYCLE_PARAMETERS})


def backend_settings(values: dict) -> BackendSettings:
    """The parameters that choose and open the device, as the core's settings of the same names
    (its scenario read); ValueError or OSError when the scenario cannot be read."""
    names = (field.name for field in dataclasses.fields(BackendSettings) if field.init)
    return BackendSettings(**{name: values[name] for name in names})


def session_config(values: dict, cap: CurrentCap, backend: BackendSettings) -> SessionConfig:
    setup = PRESETS[backend.setup_name()](current_limit_a=cap.limit_a)
    return SessionConfig(
        values["block_duration_s"], cycle_settings(values), setup, cap, values["initial_frequency_hz"], fit_tuning
    )


def current_problem(values: dict) -> str | None:
    """Why the excitation current is refused (it is above the cap), or None."""
    if values["excitation_current_a"] <= values["coil_current_cap_a"]:
        return None
    return (
        f"excitation_current_a={values['excitation_current_a']!r} exceeds "
        f"coil_current_cap_a={values['coil_current_cap_a']!r}"
    )


def tracking_changed(names) -> bool:
    """Whether any of the parameters ``names`` is one of tracking's."""
    return any(name.startswith("tracking") for name in names)


def tracking_settings(values: dict, backend: BackendSettings) -> TrackingSettings | None:
    """Tracking's kicks and ring-downs at the largest current the cap allows, planned by the
    device layer with the estimator's bound; None when tracking is off. ValueError when the scene
    has several probes or the target is out of the physics' reach."""
    if not values["tracking"]:
        return None
    scene = backend.tracking_scenario()
    current_a = values["coil_current_cap_a"]
    noise_std_t = values["tracking_noise_std_t"] or None  # 0: the scenario's noise model
    std_hz = tracking_plan.scenario_std_model(scene, cramer_rao_frequency_hz, COIL_OFF_SKIP_S, noise_std_t)
    setup = PRESETS[backend.setup_name()](current_limit_a=current_a)
    theta0_rad, target_std_t = values["tracking_theta0_rad"], values["tracking_target_std_t"]
    return tracking_plan.tracking_settings(scene, theta0_rad, target_std_t, current_a, std_hz, setup)


def settings_problem(values: dict, backend: BackendSettings) -> str | None:
    """Why ``values`` cannot drive the coils (the checks across parameters), or None."""
    reason = current_problem(values)
    if reason is None:
        try:
            cycle_settings(values)
            tracking_settings(values, backend)
        except ValueError as error:
            reason = str(error)
    return reason


def supply_problem(current_a: float, values: dict) -> str | None:
    """Why a supply current is refused (not finite, or above the cap), or None."""
    if not math.isfinite(current_a):
        return f"supply current {current_a!r} A refused: not finite"
    if abs(current_a) <= values["supply_current_cap_a"]:
        return None
    return (
        f"supply current {current_a!r} A refused: above supply_current_cap_a = "
        f"{values['supply_current_cap_a']} A (never clipped)"
    )


# A cycle request's fields, each obeying the limits of the parameter of its name; a negative
# value of the last three takes the parameter itself.
CYCLE_REQUEST_FIELDS = ("theta0_rad", "repeats", "tuning_steps", "gap_s")


def cycle_request_problem(request) -> str | None:
    """Why a cycle request (RunCycle or a MeasurementCycle goal) is refused: a field outside the
    limits of the driver's parameter of that name, or not finite. None when it may run."""
    for field in CYCLE_REQUEST_FIELDS:
        value = getattr(request, field)
        if field != "theta0_rad" and value < 0 and math.isfinite(value):
            continue  # the driver's parameter
        if (problem := spec_named(PARAMETERS, field).request_problem(value, field)) is not None:
            return problem
    return None
