"""mows-demo: the main job on the simulated device, end to end.

First calibrates the simulated probe, whose constants are deliberately not the paper's (the
``calibration`` scenario: kM +12 %, J −10 %): the calibration schedule steps the Helmholtz
pair's supply at θ0 = 0° and 180° (and the anti-Helmholtz wiring for the lever check) on the
simulated device in simulated device time, fits the probe's constants with the full potential
(``mows calibrate --simulate`` does the same), prints them against the truth and writes the
probe file that the estimator and the mapper then load by ``probe_file``. Then it
starts the node graph (driver on the first-principles simulator, estimator, mapper), runs one
rotation sweep through the mapper's action, and prints what the MOWS measured against the
truth of the simulated scene: the in-plane field and gradient from the first-principles
decomposition, what the paper's published model would have made of the same ring-downs, and
the model lab's verdict on which physics the published model is missing. Writes the lab's
HTML report. Node output goes to a log file so the terminal shows the measurement.

``--foxglove[=PORT]`` also runs the viz node, as ``mows-graph --foxglove`` does, and prints the
address to open in Foxglove once the node serves it (docs/visualisation.md).

A scene of several probes (``--scenario three_probes``) is mapped by all of them at once
(:mod:`mows_bringup.demo_probes`): no calibration, each probe against the truth at its magnet.

Every file goes into ``--out`` through the guarded writer (:mod:`mows.records.files`): a run
replaces the files of an earlier run there, never one of its scenario files, and refuses at once,
before any work, an ``--out`` that holds one of them.
"""

import argparse
import datetime
import math
import os
import pathlib
import re
import signal
import sys
import threading
import time
from collections.abc import Callable

import numpy as np
import rclpy
import yaml
from mows_msgs.action import RotationSweep
from mows_msgs.msg import ModelReport, RingdownFit
from rclpy.signals import SignalHandlerOptions

from mows.estimate.calibration.fit_constants import KnownConstants
from mows.estimate.calibration.fit_constants import calibrate_probe as fit_constants
from mows.lab import ProbeSet, analyse, write_report
from mows.lab.data.readers import read_sweep
from mows.lab.data.truth import against_truth, in_plane, in_plane_std
from mows.physics.probe import PAPER_PROBE, Probe
from mows.records.files import OutputRefused, check_output, check_outputs, writing
from mows.sim.scenario import load_scenario, scenario_file
from mows.sweep.calibration.schedule import CalibrationPlan, scenario_wirings
from mows.sweep.calibration.simulated import compare_with_truth, simulate_calibration
from mows.sweep.fast_cycle import PAPER_CYCLE, PAPER_ORIENTATIONS, map_s, scenario_cycle_plan
from mows.sweep.record import SweepPoint, SweepRecord
from mows_bringup.demo_probes import (
    LABELS,
    MAP_FILE,
    PROBE_FILES,
    SCALES,
    accepted,
    has_probes,
    sweep_client,
    write_probe_files,
)
from mows_bringup.demo_probes import parameters as probe_parameters
from mows_bringup.demo_probes import run_sweep as run_probes_sweep
from mows_bringup.graph import Graph, add_foxglove_option, say
from mows_bringup.nodes import foxglove_arguments, graph_nodes
from mows_ros.process import EXIT_BAD_PARAMETER
from mows_ros.qos import MAP_QOS, RESULT_QOS

DRIVER_CAP_A, DRIVER_MAX_DUTY, DRIVER_TURN_SETTLE_S = 10.0, 0.5, 0.5  # the driver's defaults
PROBE_FILE, SCENE_FILE, PARAMETERS_FILE = "calibrated_probe.yaml", "demo_scene.yaml", "demo_parameters.yaml"
LOG_FILE, TABLE_FILE, REPORT_FILE = "demo_nodes.log", "demo_sweep.csv", "demo_lab_report.html"
FOXGLOVE_LINE = re.compile(r"Foxglove: open (ws://\S+)")  # what the viz node logs once it serves
#: What a run writes into --out; each replaces the one an earlier run wrote.
OUTPUT_FILES = (PROBE_FILE, SCENE_FILE, PARAMETERS_FILE, LOG_FILE, TABLE_FILE, REPORT_FILE, MAP_FILE, *PROBE_FILES)


def parse_arguments(argv):
    parser = argparse.ArgumentParser(prog="mows-demo", description=__doc__.splitlines()[0])
    parser.add_argument(
        "--scenario",
        default="anti_helmholtz",
        help="simulated scene (shipped name or YAML; default: the anti-Helmholtz gradient of the "
        "paper's Fig. 4c; nearby_coil is Fig. 4d)",
    )
    parser.add_argument("--angles", type=int, default=8, help="orientations in the sweep (≥ 6)")
    parser.add_argument("--repeats", type=int, default=2, help="ring-downs per orientation")
    parser.add_argument("--tuning-steps", type=int, default=1, help="frequency-tuning excitations per orientation")
    parser.add_argument("--gap-s", type=float, default=0.2, help="pause between repeats, s (the paper: 10 s)")
    parser.add_argument(
        "--target",
        default="",
        choices=["", "B", "G", "both", "bx", "by", "gxx", "gxy", "gyy"],
        help="an adaptive sweep to σ ≤ 20 nT per field and 10 µT/m per gradient component of this "
        "quantity, with the cycle from physics (10 A kicks, no tuning); the paper's protocol "
        "time on the same device is printed beside it",
    )
    parser.add_argument("--out", default="out", help="directory for the lab report and the node log")
    parser.add_argument(
        "--record",
        metavar="DIR",
        default="",
        help="record the session into the new bag DIR (the driver's record_path): mows map, mows fit and "
        "mows lab read it later",
    )
    parser.add_argument(
        "--probe-scenario",
        default="calibration",
        help="scenario whose (not the paper's) probe is calibrated first and then mapped with",
    )
    add_foxglove_option(parser)
    args = parser.parse_args(argv)
    if args.angles < 6:
        parser.error("a sweep needs at least 6 orientations to separate field (1θ0) from gradient (2θ0)")
    for option, name in (("--scenario", args.scenario), ("--probe-scenario", args.probe_scenario)):
        try:
            load_scenario(name)
        except (OSError, ValueError, KeyError, TypeError) as error:
            sys.stderr.write(f"mows-demo: error: {option} {name}: {error}\n")
            raise SystemExit(EXIT_BAD_PARAMETER) from None
    if args.record and os.path.lexists(args.record):
        sys.stderr.write(f"mows-demo: error: --record {args.record}: exists; a recording goes into a new directory\n")
        raise SystemExit(EXIT_BAD_PARAMETER)
    if args.target and has_probes(args.scenario):
        parser.error(f"--target: the adaptive sweep takes one probe; {args.scenario} has several")
    return args


def inputs_of(args) -> tuple[pathlib.Path, pathlib.Path]:
    """The scenario files the demo reads: no output may replace them."""
    return scenario_file(args.scenario), scenario_file(args.probe_scenario)


def check_out(args) -> pathlib.Path:
    """``--out``, made if missing, if the demo may write its files there; else one line and exit
    status 2 (an --out that holds a scenario the demo reads, a file, an unwritable directory)."""
    out = pathlib.Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        check_outputs([out / name for name in OUTPUT_FILES], inputs_of(args), force=True)
    except (OSError, OutputRefused) as error:
        sys.stderr.write(f"mows-demo: error: --out {args.out}: {error}\n")
        raise SystemExit(EXIT_BAD_PARAMETER) from None
    return out


def calibrate_probe(args, directory: pathlib.Path):
    """Calibrate the probe of ``--probe-scenario`` on its simulated bench; the probe file and
    the scene to map (``--scenario`` with that probe in it), both written to ``directory``."""

    bench = load_scenario(args.probe_scenario)
    gradient = bench.replace(supply=load_scenario("calibration_gradient").supply, seed=bench.seed + 1)
    plan = CalibrationPlan(currents_a=(0.0, 1.0, 2.0, -1.0, -2.0))
    say(
        f"calibrating the probe of {args.probe_scenario}: supply {list(plan.currents_a)} A at θ0 = 0° and 180°, "
        "Helmholtz and anti-Helmholtz wiring (simulated device time)"
    )
    points = list(
        simulate_calibration(bench, plan, PAPER_PROBE, lambda f: say(f"  {f.step}/{f.steps}: {f.message}")).points
    )
    gradient_plan = CalibrationPlan(plan.currents_a, wiring="gradient")
    points += simulate_calibration(gradient, gradient_plan, PAPER_PROBE).points
    calibration = fit_constants(points, scenario_wirings(bench, gradient), KnownConstants.of(PAPER_PROBE))
    for line in compare_with_truth(calibration, bench.probe).splitlines() + [f"  {n}" for n in calibration.notes]:
        say(line)
    probe_path = directory / PROBE_FILE
    date = datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds")
    calibration.probe().to_yaml(probe_path, calibration.record(date, bench.name), inputs_of(args), force=True)
    scene_path = directory / SCENE_FILE
    load_scenario(args.scenario).replace(probe=bench.probe).to_yaml(scene_path, inputs_of(args), force=True)
    say(f"probe file: {probe_path}; the scene {args.scenario} with that probe: {scene_path}")
    return probe_path, scene_path


def write_parameters(args, directory: pathlib.Path, probe_path, scene_path) -> pathlib.Path:
    """One parameter file for the whole graph; each node takes its own section. The driver
    drives the coils of the scene's own set-up; estimator and mapper load the calibrated probe."""

    scenario = load_scenario(scene_path)
    driver = {
        "scenario": str(scene_path),
        "coil_setup": scenario.setup.name,
        "repeats": args.repeats,
        "tuning_steps": args.tuning_steps,
        "gap_s": args.gap_s,
        **recording(args),
    }
    mapper = {"reference_scenario": str(scene_path), "repeats_per_angle": args.repeats, "probe_file": str(probe_path)}
    if args.target:
        plan = scenario_cycle_plan(scenario, DRIVER_CAP_A, DRIVER_MAX_DUTY)
        driver.update(
            excitation_current_a=plan.excitation_current_a,
            excite_s=plan.excite_s,
            ringdown_s=plan.ringdown_s,
            gap_s=plan.gap_s,
            tuning_steps=plan.tuning_steps,
        )
        mapper.update(repeat_s=plan.cycle_s, turn_s=DRIVER_TURN_SETTLE_S)
    sections = {
        "/**/driver": {"ros__parameters": driver},
        "/**/estimator": {"ros__parameters": {"probe_file": str(probe_path)}},
        "/**/mapper": {"ros__parameters": mapper},
    }
    return write_sections(directory / PARAMETERS_FILE, sections, inputs_of(args))


def recording(args) -> dict:
    """The driver's parameter that records the session when ``--record`` asks for it."""
    return {"record_path": str(pathlib.Path(args.record).absolute())} if args.record else {}


def write_sections(path: pathlib.Path, sections: dict, inputs) -> pathlib.Path:
    """The graph's parameter file: one section per node."""
    with writing([path], inputs, force=True) as outputs:
        outputs.temporaries[0].write_text(yaml.safe_dump(sections))
    return path


def main(argv=None) -> int:
    args = parse_arguments(sys.argv[1:] if argv is None else argv)
    out = check_out(args)
    if has_probes(args.scenario):
        say(f"scene: {args.scenario}, {len(load_scenario(args.scenario).probes)} probes (constants from the scene)")
        probe_paths = write_probe_files(args.scenario, out, inputs_of(args))
        scene = str(scenario_file(args.scenario))
        sections = probe_parameters(args, scene, probe_paths)
        sections["/**/driver"]["ros__parameters"].update(recording(args))
        parameters = write_sections(out / PARAMETERS_FILE, sections, inputs_of(args))
        table, inputs = out / MAP_FILE, inputs_of(args)
        return run_graph(
            args, out, parameters, lambda node, spin: run_probes_sweep(node, spin, args, scene, table, inputs)
        )
    probe_path, scene_path = calibrate_probe(args, out)
    parameters = write_parameters(args, out, probe_path, scene_path)
    return run_graph(
        args, out, parameters, lambda node, spin_until: run_sweep(node, spin_until, args, out, scene_path, probe_path)
    )


def run_graph(args, out: pathlib.Path, parameters: pathlib.Path, body: Callable) -> int:
    """Start the node graph with ``parameters``, bring it up and run ``body(node, spin_until)``
    on a node of the demo's own; 0 when ``body`` succeeded and every node stopped cleanly."""
    # The nodes write into the log while they run, so it cannot be renamed into place whole:
    # it is opened in place, under the same checks as every other output.
    log = open(check_output(out / LOG_FILE, inputs_of(args), force=True), "w")
    foxglove = args.foxglove is not None
    ros_args = ["--params-file", str(parameters), *(foxglove_arguments(args.foxglove) if foxglove else [])]
    graph = Graph(graph_nodes(foxglove), ros_args, output=NodeLog(log))
    stopping = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stopping.set())
    say(f"scene: {args.scenario}; node output in {out / LOG_FILE}")
    graph.start()
    try:
        problem = graph.bring_up(stopping.is_set)
        if problem is not None:
            say(f"bring-up failed: {problem}; see {out / LOG_FILE}")
        ok = problem is None and with_node(stopping, graph.exited, body)
    finally:
        codes = graph.stop()
        log.close()
    unclean = {name: code for name, code in codes.items() if code != 0}
    if unclean:
        say(f"nodes that did not stop cleanly: {unclean}")
    return 0 if ok and not unclean else 1


class NodeLog:
    """The nodes' output, into the log file; the viz node's address also said on the terminal."""

    def __init__(self, log):
        self._log = log

    def write(self, text: str) -> None:
        self._log.write(text)
        if (found := FOXGLOVE_LINE.search(text)) is not None:
            say(f"Foxglove: open {found.group(1)}")

    def flush(self) -> None:
        self._log.flush()


def with_node(stopping: threading.Event, exited, body: Callable) -> bool:
    """``body(node, spin_until)`` on the demo's node; False, said, when a wait ran out."""
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("mows_demo")

    def spin_until(condition, timeout_s, what):
        deadline = time.monotonic() + timeout_s
        while not condition():
            if exited():
                raise TimeoutError(f"{', '.join(exited())} stopped while waiting for {what}; see the node log")
            if stopping.is_set() or time.monotonic() > deadline:
                raise TimeoutError(f"stopped waiting for {what}")
            rclpy.spin_once(node, timeout_sec=0.1)

    try:
        return body(node, spin_until)
    except TimeoutError as error:
        say(str(error))
        return False
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def run_sweep(node, spin_until, args, out: pathlib.Path, scene_path, probe_path) -> bool:
    fits, reports = [], []
    node.create_subscription(RingdownFit, "mows/ringdown", fits.append, RESULT_QOS)
    node.create_subscription(ModelReport, "mows/model_report", reports.append, MAP_QOS)
    client = sweep_client(node, spin_until)
    angles = np.radians(np.arange(args.angles) * 360.0 / args.angles)
    if args.target:
        say(f"adaptive sweep of {args.target} to σ ≤ 20 nT, 10 µT/m, cycle from physics")
        goal = RotationSweep.Goal(target=args.target)
    else:
        say(f"sweep: {args.angles} orientations × {args.repeats} ring-downs")
        goal = RotationSweep.Goal(theta0_rad=angles.tolist(), repeats_per_angle=args.repeats)
    started = time.monotonic()
    if (handle := accepted(spin_until, client, goal, lambda f: print_feedback(f.feedback))) is None:
        return False
    result = handle.get_result_async()
    spin_until(result.done, 600.0 if args.target else 60.0 + args.angles * args.repeats * 30.0, "the sweep")
    outcome = result.result().result
    if args.target:
        say(
            f"adaptive sweep: {outcome.message}; {time.monotonic() - started:.1f} s (the simulated device runs in "
            f"real time); the paper's protocol takes {map_s(PAPER_CYCLE, PAPER_ORIENTATIONS):.0f} s per "
            f"{PAPER_ORIENTATIONS}-orientation map on this "
            "device (mows bench throughput measures it to the same target)"
        )
    if not outcome.success:
        say(f"sweep failed: {outcome.message}")
        return False
    spin_until(lambda: reports, 60.0, "the model report")
    print_outcome(str(scene_path), outcome.decomposition, fits, reports[-1], out, probe_path, inputs_of(args))
    return True


def print_feedback(feedback) -> None:
    say(
        f"θ0 = {math.degrees(feedback.theta0_rad):6.1f}°  Δf = {feedback.frequency_shift_hz * 1e3:9.3f} ± "
        f"{feedback.frequency_shift_std_hz * 1e3:.3f} mHz  ({feedback.n_ok} of {len(feedback.fits)} ring-downs OK)"
    )


def print_outcome(scenario, decomposition, fits, report, out: pathlib.Path, probe_path, inputs) -> None:
    """The mapper's decomposition against the scene's truth and against the published model's
    reading of the same ring-downs, the lab's live report, and the lab run here on the sweep's
    table (written with the HTML report)."""
    probe = Probe.from_yaml(probe_path)
    record = SweepRecord([SweepPoint.from_message(fit) for fit in fits if fit.status_name == "OK"])
    readings = read_sweep(record, scenario, probe)
    value = in_plane(decomposition.field_t, decomposition.gradient_t_per_m)
    sigma = in_plane_std(decomposition.field_covariance_t2, decomposition.gradient_covariance)
    measured = against_truth(load_scenario(scenario), 0, value, sigma)
    published = in_plane(readings.published.field_t, readings.published.gradient_t_per_m)
    say("")
    say(f"{'':12s} {'first principles':>22s} {'truth':>10s} {'pull':>7s} {'published model':>17s}")
    for label, row, pub, scale in zip(LABELS, measured, published, SCALES):
        say(
            f"{label:12s} {row.value * scale:13.3f} ± {row.sigma * scale:6.3f} {row.truth * scale:10.3f} "
            f"{row.pull:7.2f} {pub * scale:17.3f}"
        )
    say(
        f"χ²/dof: first principles {decomposition.chi2_dof:.2f}, published {readings.published.chi2_dof:.2f}"
        + (
            "  (well above 1: the field is not linear over the lever; the lab below says what is missing)"
            if decomposition.chi2_dof > 3
            else ""
        )
    )
    say("")
    say(
        f"model lab, live in the mapper: the published model + {', '.join(report.effects) or 'nothing'}: "
        f"verdict {report.verdict}, χ²/dof {report.chi2_dof:.2f}"
    )
    for candidate in list(report.candidates)[:4]:
        say(
            f"  candidate {candidate.effect:22s} ΔBIC {candidate.delta_bic:10.1f}  χ²/dof after "
            f"{candidate.chi2_dof_after:.2f}  group {candidate.group}"
        )
    say(f"  residual structure: {report.structure}")
    table_path = out / TABLE_FILE
    with writing([table_path], inputs, force=True) as outputs:
        readings.table.to_csv(outputs.temporaries[0])
    say(f"sweep table: {table_path} (try: mows lab diagnose {table_path} --probe <probe.yaml>)")
    lab = analyse(readings.table, ProbeSet.one(probe), auto=True)
    for step in lab.history:
        say(
            f"  error history: {' + '.join(['published'] + step.effects):60s} χ²/dof {step.chi2_dof:9.2f}  "
            f"cv rms {step.cv_text:>8} mHz"
        )
    path = out / REPORT_FILE
    with writing([path], inputs, force=True) as outputs:
        write_report(lab, outputs.temporaries[0])
    say(f"lab report: {path}")


if __name__ == "__main__":
    sys.exit(main())
