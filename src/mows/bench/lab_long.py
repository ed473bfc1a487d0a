"""Model-lab benchmark on a long table: ``mows lab diagnose`` of a 500 000-row CSV run as a user
runs it, in a process of its own (reading and validating every row, the subsample of
``mows.cli.lab.MAX_ROWS`` rows, the analysis with cross-validation): its wall time and
peak resident memory, against the issue's bounds (a minute, 1 GiB).

The table is the 1000-row benchmark table of :mod:`mows.bench.lab` repeated, each copy its own
sweeps and with fresh noise on f_hz, written to a temporary CSV (not timed).
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from mows.bench.lab import benchmark_table

# The child reports its own peak memory (getrusage of the bench process would mix in other suites).
CHILD = (
    "import resource, runpy, sys\n"
    "sys.argv = ['mows'] + sys.argv[1:]\n"
    "try:\n    runpy.run_module('mows.cli.main', run_name='__main__')\n"
    "finally:\n    print('peak_rss_kb', resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)\n"
)


def long_table(rows: int, seed: int = 1):
    base = benchmark_table()
    copies = -(-rows // len(base))
    rng = np.random.default_rng(seed)
    columns = {name: np.tile(values, copies)[:rows] for name, values in base.columns.items()}
    columns["sweep"] = (
        np.repeat(np.arange(copies), len(base)) * (base.sweep_ids.max() + 1) + np.tile(base.sweep_ids, copies)
    )[:rows]
    columns["f_hz"] = columns["f_hz"] + rng.normal(0.0, 1.0, rows) * columns["f_std_hz"]
    return dataclasses.replace(base, columns=columns)


def run(rows: int = 500_000) -> dict:
    """Wall seconds and peak MiB of ``mows lab diagnose --json`` on a ``rows``-row CSV."""
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "long.csv"
        long_table(rows).to_csv(path)
        start = time.perf_counter()
        result = subprocess.run(
            [sys.executable, "-c", CHILD, "lab", "diagnose", str(path), "--json"], capture_output=True, text=True
        )
        seconds = time.perf_counter() - start
    peak_kb = next((int(line.split()[1]) for line in result.stderr.splitlines() if line.startswith("peak_rss_kb")), 0)
    analysed = json.loads(result.stdout)["base"]["n"] if result.returncode == 0 else None
    return {
        "rows": rows,
        "analysed_rows": analysed,
        "exit_status": result.returncode,
        "diagnose_s": seconds,
        "target_s": 60.0,
        "peak_rss_mib": peak_kb / 1024,
        "memory_bound_mib": 1024,
    }


if __name__ == "__main__":
    print(run())
