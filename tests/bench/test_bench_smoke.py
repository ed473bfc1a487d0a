"""Every ``mows bench`` suite runs: ``mows bench SUITE --quick --json`` as a user runs it, in a
process of its own, exits 0 and reports its figures as finite numbers. The figures themselves
are never asserted (the machine is shared); a suite that breaks fails here instead of in the
next ``make bench``. The suites that start the node graph (stream, latency_tracking) are ROS
tests in the "realtime" group, as they run nodes in real time; the latency suite is run with its
load, by tests/ros/test_latency_load.py."""

import json
import math
import subprocess
import sys

import pytest

from mows.bench import cycle_simulation
from mows.cli.bench import SUITES
from mows.cli.main import main
from mows.cli.status import EXIT_BUG

LATENCY = (
    "latency_ms_median",
    "latency_ms_p99",
    "latency_ms_max",
    "ringdowns",
    "fits",
    "blocks",
    "cycles_s",
)
# Figures each suite's --quick run reports, all finite numbers.
FIGURES = {
    "estimator": (
        "fit_ms_median",
        "curve_fit_ms_median",
        "speedup",
        "fit_std_over_crb",
        "efficiency_min",
        "std_over_crb_max",
        "bias_max_sigma",
        "cells_with_crb_below_5mhz",
    ),
    "simulator": (
        "cycle_ms_median",
        "cycle_ms_without_noise",
        "kernel_ms_per_second_free",
        "solve_ivp_dop853_ms_per_cycle",
        "solve_ivp_over_simulator",
        "max_theta_difference_cycle_rad",
        "max_theta_difference_free_ringdown_rad",
        "three_probes_read_ms_per_second_driven",
        "three_probes_driven_over_one_probe",
    ),
    "stream": ("baseline_generation_share", "session_share", "session_overhead_share", "session_blocks"),
    "lab": ("rows", "effects", "diagnose_s"),
    "lab_long": ("rows", "compare_s", "compare_cpu_s", "compare_peak_rss_mib", "compare_analysed_rows"),
    "multiprobe": (
        "fit_ms_median",
        "joint_over_single",
        "failures",
        "worst_std_over_crb_10hz",
        "sep_2hz_ratio_1_probe1_crb_over_alone",
    ),
    "latency_tracking": LATENCY,
    "viz": (
        "draw_ms_median",
        "draw_whole_window_ms_median",
        "draw_blas_product_ms_median",
        "draw_to_ringdown_ratio",
        "blas_product_ratio",
    ),
    "workspace": (
        "b_error",
        "g_error",
        "b_pull_sd",
        "g_pull_sd",
        "hall_b_error",
        "points_ratio",
        "sweep_minutes",
        "pose_eiv_b_error",
        "pose_naive_b_error",
    ),
    "throughput": (
        "adaptive_s",
        "adaptive_ringdowns",
        "demo_s",
        "plan_ringdown_s",
        "tracking_hz",
        "tracking_std_t",
        "points_per_minute_1_probe",
        "points_per_minute_3_probes",
        "points_per_minute_ratio",
    ),
}
# tests/ros/test_latency_load.py runs the latency suite's --quick --load: its baseline is the
# stream of cycles without the load, and latency_tracking here runs the same tool by --cycles.
SMOKED_ELSEWHERE = {"latency"}
NEEDS_ROS = {"stream", "latency_tracking"}
SLOW = {"lab_long", "throughput"}  # ~10 s of CPU each, more beside other work


def suite_param(name: str):
    marks = [pytest.mark.ros, pytest.mark.xdist_group("realtime")] if name in NEEDS_ROS else []
    return pytest.param(name, marks=marks + ([pytest.mark.slow] if name in SLOW else []), id=name)


def test_every_suite_is_smoke_tested():
    assert set(FIGURES) | SMOKED_ELSEWHERE == set(SUITES) and not set(FIGURES) & SMOKED_ELSEWHERE


@pytest.mark.parametrize("suite", [suite_param(name) for name in SUITES if name not in SMOKED_ELSEWHERE])
def test_a_quick_run_of_the_suite_reports_finite_figures(suite):
    run = subprocess.run(
        [sys.executable, "-m", "mows.cli.main", "bench", suite, "--quick", "--json"],
        capture_output=True,
        text=True,
        timeout=500,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    figures = json.loads(run.stdout)[suite]
    for key in (*FIGURES[suite], "wall_s"):
        value = figures.get(key)
        assert isinstance(value, (int, float)) and not isinstance(value, bool), (key, value)
        assert math.isfinite(value), (key, value)
    if suite == "lab_long":  # its commands run as child processes: their status is a figure
        assert figures["compare_exit_status"] == 0, figures


def test_a_suite_that_raises_is_a_bug_with_its_traceback(monkeypatch, capsys):
    def broken(**options):
        raise ValueError("operands could not be broadcast together")

    monkeypatch.setattr(cycle_simulation, "run", broken)
    assert main(["bench", "simulator", "--quick", "--json"]) == EXIT_BUG
    error = capsys.readouterr().err
    assert "Traceback" in error and "ValueError: operands could not be broadcast" in error
    assert "internal error in the simulator suite" in error


def test_a_suite_that_measured_nothing_fails_the_run(monkeypatch, capsys):
    monkeypatch.setattr(
        cycle_simulation, "run", lambda **options: {"failed": "[graph] bring-up failed:\n driver refused"}
    )
    assert main(["bench", "simulator", "--quick"]) == EXIT_BUG
    assert "the simulator suite measured nothing: [graph] bring-up failed: driver refused" in capsys.readouterr().err


def test_an_unknown_suite_is_a_bad_input(capsys):
    assert main(["bench", "simulatr"]) == 2
    assert "error: argument SUITE: unknown suite 'simulatr'" in capsys.readouterr().err
