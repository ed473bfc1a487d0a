"""The calibrator's parameter table, with the checks that its scenarios and nominal probe exist,
and the bench they describe."""

from mows.physics.probe import PAPER_PROBE, Probe
from mows.sim.scenario import load_scenario
from mows.sweep.calibration.run import Bench
from mows.sweep.calibration.schedule import UNIPOLAR_CURRENTS_A, scenario_wirings
from mows_ros import operator
from mows_ros.params import ParamSpec
from mows_ros.probe import probe_file_problem


def scenario_problem(parameter: str, name: str) -> str | None:
    """Why ``name`` is no scenario with a supply section, or None ('' is allowed: none)."""
    try:
        if name and load_scenario(name).supply is None:
            return f"{parameter}={name!r} has no supply section: the supply's field per ampere is unknown"
    except (OSError, ValueError) as error:
        return f"{parameter}={name!r}: {error}"
    return None


def nominal_probe_problem(path: str) -> str | None:
    """Why ``nominal_probe_file`` cannot be read, or None ('' is the paper's probe)."""
    problem = probe_file_problem(path) if path else None
    return None if problem is None else f"nominal_{problem}"  # probe_file_problem says probe_file=…


PARAMETERS = (
    ParamSpec(
        "scenario",
        "calibration",
        "scenario whose supply section describes the homogeneous wiring (the "
        "Helmholtz pair's field per ampere at the probe)",
        check=lambda v: scenario_problem("scenario", v or "?"),
    ),
    ParamSpec(
        "gradient_scenario",
        "calibration_gradient",
        "scenario whose supply section describes the gradient wiring (anti-Helmholtz); '' for none",
        check=lambda v: scenario_problem("gradient_scenario", v),
    ),
    ParamSpec(
        "nominal_probe_file",
        "",
        "probe YAML giving the magnet's moment, mass and the housing stop ('' the paper's)",
        check=nominal_probe_problem,
    ),
    ParamSpec(
        "probe_output_file",
        "calibrated_probe.yaml",
        "where a goal without probe_output_file writes the calibrated probe",
        formerly=("probe_file",),
    ),
    ParamSpec("hardware_id", "", "written to the probe file ('' the scenario's name)"),
    ParamSpec(
        "currents_a",
        list(UNIPOLAR_CURRENTS_A),
        "supply currents of a goal that lists none, A (the default runs on a unipolar supply too: "
        "θ0 = 180° gives the field's other sign)",
    ),
    ParamSpec(
        "probe_id",
        0,
        "the probe this calibrates, of those the estimator's probes parameter lists: only its ring-down "
        "fits are used, the others' counted in the result (0: a single probe)",
        range=(0, 255),
    ),
    ParamSpec("cycle_timeout_s", 300.0, "longest wait for the driver's cycle, s", range=(1.0, 3600.0)),
    ParamSpec("supply_timeout_s", 60.0, "longest wait for the supply to reach a current, s", range=(1.0, 3600.0)),
    ParamSpec("fit_timeout_s", 10.0, "longest wait for the fits of a finished cycle, s", range=(0.1, 600.0)),
    *operator.PARAMETERS,
)


def bench_of(values: dict) -> Bench:
    """The bench the parameter ``values`` describe."""
    scenario = load_scenario(values["scenario"])
    gradient = load_scenario(values["gradient_scenario"]) if values["gradient_scenario"] else None
    nominal_file = values["nominal_probe_file"]
    nominal = Probe.from_yaml(nominal_file) if nominal_file else PAPER_PROBE
    wirings = scenario_wirings(scenario, gradient)
    return Bench(wirings, scenario.supply.name, nominal, values["hardware_id"] or scenario.name, nominal_file)
