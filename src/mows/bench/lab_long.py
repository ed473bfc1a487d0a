"""Model-lab benchmark on a long table: ``mows lab diagnose``, ``compare`` and ``add EFFECT`` of a
500 000-row CSV run as a user runs them, each in a process of its own (reading and validating
every row, the stratified subsample of at most ``mows.cli.lab.MAX_ROWS`` rows, the analysis
with cross-validation): wall time, CPU time and peak resident memory of each, against the
bounds it must meet (a minute, 1 GiB). The CPU time says what the work costs on a machine
shared with others, where the wall time also counts the waiting for a core.

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

# ``add`` with the effect diagnose names first on this table (``add --auto`` runs the stepwise
# search, a cost of the search itself, see docs/model_lab.md).
COMMANDS = {"diagnose": ["diagnose"], "compare": ["compare"], "add": ["add", "transverse_gradient"]}
# The child reports its own peak memory and CPU time (getrusage of the bench process would mix in
# other suites).
CHILD = (
    "import resource, runpy, sys\n"
    "sys.argv = ['mows'] + sys.argv[1:]\n"
    "try:\n    runpy.run_module('mows.cli.main', run_name='__main__')\n"
    "finally:\n"
    "    usage = resource.getrusage(resource.RUSAGE_SELF)\n"
    "    print('usage', usage.ru_maxrss, usage.ru_utime + usage.ru_stime, file=sys.stderr)\n"
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


def run(rows: int = 500_000, commands=tuple(COMMANDS)) -> dict:
    """Figures of ``mows lab COMMAND --json`` on a ``rows``-row CSV for each of ``commands``."""
    figures: dict = {"rows": rows, "target_s": 60.0, "memory_bound_mib": 1024}
    with tempfile.TemporaryDirectory() as directory:
        path = Path(directory) / "long.csv"
        long_table(rows).to_csv(path)
        for name in commands:
            figures.update({f"{name}_{key}": value for key, value in _timed(COMMANDS[name], path).items()})
    return figures


def _timed(command: list, path: Path) -> dict:
    start = time.perf_counter()
    result = subprocess.run(
        [sys.executable, "-c", CHILD, "lab", command[0], str(path), *command[1:], "--json"],
        capture_output=True,
        text=True,
    )
    seconds = time.perf_counter() - start
    usage = next((line.split()[1:] for line in result.stderr.splitlines() if line.startswith("usage ")), ["0", "nan"])
    report = json.loads(result.stdout) if result.returncode == 0 else {}
    return {
        "exit_status": result.returncode,
        "s": seconds,
        "cpu_s": float(usage[1]),
        "peak_rss_mib": int(usage[0]) / 1024,
        "analysed_rows": report.get("base", {}).get("n"),
        "effects": report.get("effects"),
    }


if __name__ == "__main__":
    print(run())
