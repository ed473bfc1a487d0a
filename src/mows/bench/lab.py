"""Model-lab benchmark: ``diagnose`` with the whole catalog on a 1000-row table (target < 5 s on
one core).

The table: 10 rotation sweeps of 100 orientations in an anti-Helmholtz gradient (≈ 10 mT/m)
plus an Earth-like field, with temperature, time and amplitude columns so that every catalog
effect is testable; truth from exact sources (:mod:`mows.lab.data.synthetic`). The timing covers the
base fit and the diagnosis (candidate signatures, refits, groups, separating measurements,
verdict), not building the table.
"""

from __future__ import annotations

import time

import numpy as np

from mows.lab import FrequencyModel, catalog, diagnose
from mows.lab.data import synthetic
from mows.physics.field import UniformField, anti_helmholtz_pair
from mows.physics.probe import PAPER_PROBE

ROWS_PER_SWEEP = 100
SWEEPS = 10


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


def run(sweeps: int = SWEEPS) -> dict:
    """Seconds for one ``diagnose`` with the whole catalog on the table of ``sweeps`` sweeps
    (1000 rows by default), and what it found."""
    table = benchmark_table(sweeps=sweeps)
    effects = list(catalog().values())
    start = time.perf_counter()
    fit = FrequencyModel(PAPER_PROBE).fit(table)
    result = diagnose(fit, effects)
    seconds = time.perf_counter() - start
    return {
        "rows": len(table),
        "effects": len(effects),
        "diagnose_s": seconds,
        "target_s": 5.0,
        "verdict": result.verdict,
        "best": result.best.name if result.best else None,
        "untestable": sorted(result.untestable),
    }


if __name__ == "__main__":
    print(run())
