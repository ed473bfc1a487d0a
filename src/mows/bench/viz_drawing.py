"""Live-view benchmark: one ring-down drawn as the viz node draws it, against the ring-down's
own duration (a drawing longer than the ring-downs come falls behind), where the fit leaves
θmax undetermined (the costly case: a grid of least squares, :mod:`mows.viz.curves`).

- ``draw_ms_median``: the plot's curve at its plotted points (``ViewSettings.max_points``).
- ``draw_whole_window_ms_median``: the same curve at every sample of the window.
- ``draw_blas_product_ms_median``: the plotted points with the pickup series summed as a
  complex matrix product (``@``, a BLAS call) instead of a sum; on a loaded host a threaded
  BLAS waits on its threads, so ``blas_product_ratio`` is about 1 on an idle machine and far
  above it on a loaded one (``load_average_1min`` says which).

The ring-down: one simulated cycle of the default scene, fitted as the estimator fits it.
"""

from __future__ import annotations

import dataclasses
import math
import os

import numpy as np

from mows.bench.cycle_simulation import median_ms
from mows.device.stream.simulated_cycle import simulate_cycle
from mows.estimate.recorded_cycle import fit_cycle
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice
from mows.viz.curves import RingdownModel, ringdown_curve, stride
from mows.viz.view import ViewSettings


class _ProductSeries(RingdownModel):
    """The pickup series as a complex matrix product (the baseline of the module docstring)."""

    def series(self, t_s, amplitude_rad):
        terms = np.exp(1j * np.multiply.outer(self.deflection_rad(t_s, amplitude_rad), np.arange(len(self.pickup))))
        return np.real(terms @ np.asarray(self.pickup, complex))


def ringdown(seed: int = 0) -> tuple[np.ndarray, float, RingdownModel]:
    """A fitted window's samples, their rate, and its fit's model with θmax undetermined."""
    scenario = load_scenario()
    device = SimulatedDevice(scenario, np.random.default_rng(seed))
    record = simulate_cycle(device, 0.0, scenario.excitation.amplitude_a)
    fit = fit_cycle(record, scenario)
    first = record.coil_off_index + round(fit.start_offset_s * record.sample_rate_hz)
    samples = record.samples_t[first : first + fit.n_samples]
    numbers = {name: float(getattr(fit, name)) for name in ("frequency_hz", "damping_per_s", "phase_rad")}
    model = RingdownModel(
        **numbers, amplitude_rad=math.nan, kappa_t=float(fit.kappa_t), offset_t=float(fit.offset_t), pickup=fit.pickup
    )
    return samples, record.sample_rate_hz, model


def run(repeats: int = 10) -> dict:
    samples, rate_hz, model = ringdown()
    settings = ViewSettings()
    every = stride(len(samples), settings.max_points)
    product = _ProductSeries(**{f.name: getattr(model, f.name) for f in dataclasses.fields(model)})
    load = os.getloadavg()[0]
    figures = {
        "ringdown_s": len(samples) / rate_hz,
        "plotted_points": len(range(0, len(samples), every)),
        "draw_ms_median": median_ms(lambda: ringdown_curve(samples, rate_hz, model, settings.channels, every), repeats),
        "draw_whole_window_ms_median": median_ms(
            lambda: ringdown_curve(samples, rate_hz, model, settings.channels), repeats
        ),
        "draw_blas_product_ms_median": median_ms(
            lambda: ringdown_curve(samples, rate_hz, product, settings.channels, every), repeats
        ),
    }
    figures["draw_to_ringdown_ratio"] = figures["draw_ms_median"] / 1e3 / figures["ringdown_s"]
    figures["blas_product_ratio"] = figures["draw_blas_product_ms_median"] / figures["draw_ms_median"]
    figures["load_average_1min"] = (load + os.getloadavg()[0]) / 2
    return figures
