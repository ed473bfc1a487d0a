"""Model-lab benchmark on 1000-row tables, each figure on one core (target < 5 s).

- ``diagnose_s``: ``diagnose`` with the whole catalog. The table: 10 rotation sweeps of 100
  orientations in an anti-Helmholtz gradient (≈ 10 mT/m) plus an Earth-like field, with
  temperature, time and amplitude columns so that every catalog effect is testable. The timing
  covers the base fit and the diagnosis (candidate signatures, refits, groups, separating
  measurements, verdict).
- ``auto_s``: ``mows lab add --auto`` (the stepwise search, cross-validated history, the
  discovery beyond the catalog and the report) on a table whose missing physics is outside the
  catalog: the magnet's moment falls by 1e-3/K while the probe warms 10 K over 42 sweeps of 24
  orientations in a 0.43 mT field (every row its own temperature, so every model with a thermal
  term evaluates every row). ``auto_effects`` and ``auto_families`` say what it found: the
  catalog's physics that is there, and the term family of what is not.

Each figure is wall time (``_s``) and the process's CPU time (``_cpu_s``): with BLAS on one
thread the work runs on one core, so on a shared machine the CPU time is what the wall time
would be on a quiet one, and the wall time what a user waits for beside the load. Truths from
exact sources (:mod:`mows.lab.data.synthetic`); building the tables is not timed.
"""

from __future__ import annotations

import time

import numpy as np
from threadpoolctl import threadpool_limits

from mows.lab import FrequencyModel, ProbeSet, analyse, catalog, diagnose
from mows.lab.data import synthetic
from mows.physics.field import UniformField, anti_helmholtz_pair
from mows.physics.probe import PAPER_PROBE

ROWS_PER_SWEEP = 100
SWEEPS = 10
OUTSIDE_SWEEPS = 42  # of 24 orientations: 1008 rows
MOMENT_PER_K = -1e-3  # NdFeB's moment, outside the catalog
WARMING_K = 10.0


def benchmark_table(seed: int = 0, sweeps: int = SWEEPS):
    """The table described in the module docstring (``sweeps`` × 100 rows)."""
    sweep = synthetic.rotation_sweeps(360.0 / ROWS_PER_SWEEP, sweeps, seconds_per_row=10.0)
    theta0 = sweep.pop("theta0_deg")
    temperature = 293.15 + 0.5 * np.sin(2 * np.pi * sweep["t_s"] / 3000.0)
    source = anti_helmholtz_pair((0, 0, 0), (1, 0, 0), 0.105, 100, 1.0) + UniformField((15e-6, -12e-6, -40e-6))
    return synthetic.synthesize(
        PAPER_PROBE,
        source,
        theta0,
        np.random.default_rng(seed),
        amplitude_deg=20.0,
        temperature_k=temperature,
        t_s=sweep["t_s"],
        sweep=sweep["sweep"],
    )


def outside_catalog_table(seed: int = 0, sweeps: int = OUTSIDE_SWEEPS):
    """The ``auto_s`` table of the module docstring (``sweeps`` × 24 rows)."""
    sweep = synthetic.rotation_sweeps(15.0, sweeps)
    theta0 = sweep.pop("theta0_deg")
    rng = np.random.default_rng(seed)
    warming = WARMING_K * sweep["t_s"] / max(float(np.ptp(sweep["t_s"])), 1.0)
    temperature = PAPER_PROBE.reference_temperature_k + warming + rng.uniform(-0.5, 0.5, len(theta0))
    source = UniformField((4e-4, 1.5e-4, -4e-5))
    magnet = PAPER_PROBE.replace(moment_temp_coeff_per_k=MOMENT_PER_K)
    truth = synthetic.true_frequency_hz(magnet, source, np.radians(theta0), np.radians(2.0), temperature)
    return synthetic.synthesize(
        PAPER_PROBE,
        source,
        theta0,
        rng,
        3.3e-4,
        2.0,
        temperature,
        truth_hz=truth,
        t_s=sweep["t_s"],
        sweep=sweep["sweep"],
    )


def run(sweeps: int = SWEEPS, outside_sweeps: int = OUTSIDE_SWEEPS) -> dict:
    """Seconds for one ``diagnose`` with the whole catalog on the table of ``sweeps`` sweeps
    (1000 rows by default) and for one ``add --auto`` on the outside-catalog table of
    ``outside_sweeps`` sweeps (1008 rows), on one core, and what they found."""
    table = benchmark_table(sweeps=sweeps)
    effects = list(catalog().values())
    outside = outside_catalog_table(sweeps=outside_sweeps)
    probes = ProbeSet.one(PAPER_PROBE)
    with threadpool_limits(1):
        start, cpu = time.perf_counter(), time.process_time()
        fit = FrequencyModel(probes).fit(table)
        result = diagnose(fit, effects, probes)
        seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
        start, cpu = time.perf_counter(), time.process_time()
        auto = analyse(outside, probes, auto=True)
        auto_seconds, auto_cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    return {
        "rows": len(table),
        "effects": len(effects),
        "diagnose_s": seconds,
        "diagnose_cpu_s": cpu_seconds,
        "target_s": 5.0,
        "verdict": result.verdict,
        "best": result.best.name if result.best else None,
        "untestable": sorted(result.untestable),
        "auto_rows": len(outside),
        "auto_s": auto_seconds,
        "auto_cpu_s": auto_cpu_seconds,
        "auto_effects": auto.effects,
        "auto_verdict": auto.verdict,
        "auto_families": [] if auto.discovery is None else [term.family for term in auto.discovery.terms],
    }


if __name__ == "__main__":
    print(run())
