"""``mows bench latency --load`` runs and reports its figures (a smoke run of the benchmark:
its figures are reported, never asserted, since the machine is shared).

The checks are what must hold whatever the machine's speed: the stream ran for the asked
duration beside the load, the JointState loop published at most at its asked rate and was heard
in another process, and every figure docs/performance.md quotes is there."""

import json

import pytest

from mows.cli.bench import QUICK
from mows.cli.main import main

pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.xdist_group("realtime")]

QUICK_LOAD_DURATION_S = QUICK["latency"]["load_duration_s"]


def test_the_latency_bench_runs_under_load_and_reports_it(capsys):
    assert main(["bench", "latency", "--load", "--quick", "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)["latency"]
    # A stream that fitted nothing (or a graph that failed) comes back as its stderr's tail.
    assert "failed" not in figures and "failed" not in figures["baseline"], figures
    assert figures["ringdowns"] > 0, figures
    for key in ("latency_ms_median", "latency_ms_p99", "latency_ms_max"):
        assert figures[key] > 0, (key, figures)
    assert figures["latency_ms_median"] <= figures["latency_ms_p99"] <= figures["latency_ms_max"]
    assert figures["cycles"] >= 1 and figures["cycles_s"] >= QUICK_LOAD_DURATION_S
    assert figures["blocks"] > 0
    # The estimator's own gap count (from /diagnostics) and this listener's.
    for key in ("gaps", "missing_samples", "listener_gaps", "listener_missing_samples", "fits_data_gap"):
        assert figures[key] >= 0, (key, figures)
    load = figures["load"]
    assert load["cpu_burners"] == 2 and load["joint_state_asked_hz"] == 1000.0
    assert load["burner_nice"] == 19  # a smoke run: the burners leave the tests beside it their cores
    assert figures["realtime_priority"] == 0 and "default_priority" not in figures  # the graph as it is
    # Deadlines are absolute and a missed tick is skipped: never faster than asked.
    assert 0 < load["joint_state_published_hz"] <= 1000.0 * 1.001
    assert load["joint_state_received_hz"] > 0
    assert load["load_average_1min_start"] >= 0 and load["load_average_1min_end"] >= 0
    # The same stream without the load, timed in the same run.
    baseline = figures["baseline"]
    assert baseline["ringdowns"] > 0 and baseline["cycles_s"] >= QUICK_LOAD_DURATION_S and "load" not in baseline
