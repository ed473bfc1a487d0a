"""``mows bench``: benchmark figures of the simulator, the estimator, the stream and the lab.

Every figure is measured in this run, against a baseline timed in the same run where there is
one (scipy's solve_ivp for the simulator, curve_fit for the estimator, generating the samples
without publishing them for the stream). Nothing here fails on a figure: machines are shared
and noisy, so speed is reported, not asserted. ``--json`` prints the figures as one JSON
object (the estimator's keys are top level: fit_ms_median, curve_fit_ms_median,
efficiency_min, bias_max_sigma, and the throughput's paper_s, default_s, adaptive_s, tracking_hz …).
A suite that raises is a bug, not a bad input: its traceback goes to stderr, the other suites
still run, and the exit status is 1 (2 is kept for an unknown suite's name). So is a suite that
ran but measured nothing (a ``failed`` figure: the node graph did not come up).
"""

import argparse
import importlib
import json
import math
import sys
import time
import traceback

from mows.cli.status import EXIT_BUG
from mows.records.json_numbers import finite_or_none

SUITES = {
    "estimator": ("mows.bench.estimator", "ring-down fit: speed against curve_fit, precision against the CRB"),
    "simulator": ("mows.bench.cycle_simulation", "one measurement cycle, against solve_ivp"),
    "stream": ("mows.bench.streaming", "CPU share of one core to stream 20 kS/s × 2 channels"),
    "lab": ("mows.bench.lab_diagnose", "model lab diagnose on 1000 rows with the whole catalog"),
    "lab_long": ("mows.bench.lab_long", "mows lab diagnose on a 500 000-row CSV: wall time and peak memory"),
    "latency": ("mows.bench.latency", "last sample of a ring-down to its published fit, in the node graph"),
    "latency_tracking": ("mows.bench.latency_tracking", "the same in the driver's tracking mode"),
    "multiprobe": ("mows.bench.multiprobe", "two probes in one ring-down: joint fit against the bound, 2–20 Hz apart"),
    "viz": ("mows.bench.viz_drawing", "one ring-down drawn by the live view, θmax undetermined: ms per ring-down"),
    "workspace": (
        "mows.bench.workspace",
        "workspace map of an 8-coil system: B-and-G sweeps against a Hall-probe map, points to 0.05 %",
    ),
    "throughput": (
        "mows.bench.throughput",
        "device seconds to σ ≤ 20 nT, 10 µT/m: paper, default, demo and adaptive sweeps; tracking rate",
    ),
}
# Run when no suite is named: throughput simulates minutes of device time and is asked for by
# name, and so are latency_tracking (a second graph run) and multiprobe (a thousand joint fits).
DEFAULT_SUITES = ("estimator", "simulator", "stream", "lab", "lab_long", "latency")
# Figures of the throughput suite that --json also carries at the top level.
THROUGHPUT_KEYS = (
    "paper_s",
    "default_s",
    "demo_s",
    "adaptive_s",
    "tracking_hz",
    "tracking_std_t",
    "tracking_1ut_hz",
    "tracking_1ut_std_t",
    "points_per_minute",
    "points_per_minute_ratio",
)
# --quick: a smoke run of every suite (tests/bench/test_bench_smoke.py runs them all in make test, a
# few seconds of CPU each): every code path of a suite, on less data, so its figures are rough.
QUICK: dict[str, dict[str, object]] = {
    "estimator": {"trials": 10, "step_deg": 45.0, "speed_trials": 10, "baseline_trials": 3},
    "simulator": {"repeats": 3, "first_call": False},
    "lab": {"sweeps": 2, "outside_sweeps": 4},
    "stream": {"duration_s": 3.0},
    # a quick --load is a smoke run beside other work (make test): its burners yield (nice 19)
    # and the graph keeps the default policy (one loaded stream, not two; SCHED_FIFO nodes
    # starting up beside a test of the simulated NI card made its output underflow). 12 s holds
    # two cycles of 5 ring-downs without the load (about 6 s each); under it, at the default
    # policy, one cycle can take half a minute on an idle machine (3 of 5 fitted, the stream's
    # samples half lost), and the run ends after the first cycle that ends past 12 s.
    "latency": {
        "cycles": 1,
        "repeats": 5,
        "load_duration_s": 12.0,
        "burner_nice": 19,
        "realtime_priority": 0,
        "three_probe_map": False,  # a three-probe graph run of minutes: tests/ros/test_three_probe_graph.py runs it
    },
    "latency_tracking": {"cycles": 2, "repeats": 5},
    "viz": {"repeats": 2},
    "multiprobe": {"trials": 4, "separations_hz": (2.0, 10.0), "ratios": (1.0,)},
    # above the lab's subsample of mows.cli.lab.MAX_ROWS rows, so that the subsampling runs
    "lab_long": {"rows": 5_000, "commands": ("compare",)},
    # a goal 100× looser, few sweeps and low degrees: every path, rough figures
    "workspace": {
        "sweep_counts": (6, 8),
        "hall_counts": (20, 30),
        "degrees": (2, 3),
        "held_out": 50,
        "target_b": 5e-2,
        "target_g": 0.5,
        "pose_errors": ((1e-3, 1.0),),
        "pose_draws": 2,
        "lever_cases": ((8, 1.0),),
        "lever_degree": 3,
    },
    # a goal 5× looser than the default: 25× less device time
    "throughput": {
        "protocols": ("demo",),
        "tracking_updates": 5,
        "field_std_t": 100e-9,
        "gradient_std_t_per_m": 50e-6,
        "multiprobe_field_std_t": 1e-6,
        "multiprobe_gradient_std_t_per_m": 1e-3,
        "multiprobe_points": 5,
        "multiprobe_sweeps": 1,
    },
}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "suites",
        nargs="*",
        metavar="SUITE",
        type=suite,
        help=f"which benchmarks (default: {', '.join(DEFAULT_SUITES)}): {', '.join(SUITES)}",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    parser.add_argument("--quick", action="store_true", help="fewer trials (rough figures, for a smoke run)")
    parser.add_argument(
        "--load",
        action="store_true",
        help="latency: a 60 s stream beside CPU burners and a 1 kHz JointState loop (a robot's control loop)",
    )
    parser.add_argument(
        "--burners",
        type=positive_count,
        default=2,
        metavar="N",
        help="latency --load: how many CPU burners beside the graph (default 2)",
    )
    parser.add_argument(
        "--map-runs",
        type=positive_count,
        default=1,
        metavar="N",
        help="latency: run the three-probe demo N times and report the median delay of its map (default 1)",
    )


def positive_count(text: str) -> int:
    """A count of at least 1, or argparse's refusal."""
    try:
        count = int(text)
    except ValueError:
        count = 0
    if count < 1:
        raise argparse.ArgumentTypeError(f"expected a whole number of at least 1, got {text!r}")
    return count


def suite(name: str) -> str:
    """A benchmark suite's name, or argparse's refusal naming the ones there are."""
    if name not in SUITES:
        raise argparse.ArgumentTypeError(f"unknown suite {name!r}: choose from {', '.join(SUITES)}")
    return name


def run(args) -> int:
    figures, failed = {}, []
    for name in args.suites or list(DEFAULT_SUITES):
        module_name, what = SUITES[name]
        if not args.json:
            print(f"== {name}: {what}", flush=True)
        start = time.perf_counter()
        options = dict(QUICK.get(name, {}) if args.quick else {})
        if name == "latency":
            if args.load:
                options["load"] = True
            options["burners"], options["three_probe_runs"] = args.burners, args.map_runs
        try:
            result = importlib.import_module(module_name).run(**options)
        except Exception:  # noqa: BLE001 - a benchmark has no user input: whatever it raises is a bug
            print(f"mows bench: internal error in the {name} suite (a bug, please report it):", file=sys.stderr)
            traceback.print_exc()
            failed.append(name)
            continue
        result["wall_s"] = time.perf_counter() - start
        figures[name] = result
        if "failed" in result:  # a suite that ran but measured nothing (its graph did not come up)
            reason = " ".join(str(result["failed"]).split())
            print(f"mows bench: the {name} suite measured nothing: {reason}", file=sys.stderr)
            failed.append(name)
        if not args.json:
            for key, value in result.items():
                print(f"   {key:40s} {_format(value)}")
    if args.json:
        flat = dict(figures.get("estimator", {}))
        flat.update({key: value for key, value in figures.get("throughput", {}).items() if key in THROUGHPUT_KEYS})
        flat.update({name: values for name, values in figures.items()})
        print(json.dumps(finite_or_none(flat), indent=1, default=_jsonable, allow_nan=False))
    if failed:
        print(f"mows bench: {', '.join(failed)} failed (see above)", file=sys.stderr)
        return EXIT_BUG
    return 0


def _format(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}" if math.isfinite(value) else str(value)
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_format(v) for v in value) + "]"
    return str(value)


def _jsonable(value):
    if hasattr(value, "tolist"):
        return finite_or_none(value.tolist())
    return str(value)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="mows bench", description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
