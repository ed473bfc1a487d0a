"""Simulator benchmark: one measurement cycle of the default scenario, and a solve_ivp baseline.

A cycle is 0.5 s of excitation (2 A, the probe hammers against the stop) and 0.5 s of ring-down
at 20 kS/s, two fluxgate channels with noise. Figures: the median time per cycle with and
without noise, the kernel's share, numba's compilation (fresh cache) and cache-load time in a
new process, and the same cycle's equation of motion integrated by
``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-10) on the same torque function.

The same device with several probes (the three_probes scene, what the driver's sim backend
reads for it): the median time to read one second of device time, driven by the probes' summed
tones and ringing freely, against one second read with one probe in the same run. Real time is
1000 ms per second.
"""

from __future__ import annotations

import math
import os
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
from scipy.integrate import solve_ivp

from mows.device.cycle.tone_groups import plan_probes
from mows.device.stream.simulated_cycle import simulate_cycle
from mows.physics.coils import excitation_samples
from mows.physics.fluxgate import NoiseModel
from mows.physics.multitone import coil_amplitudes_a
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

_FIRST_CALL = """
import time
start = time.perf_counter()
from mows.sim.scenario import Scenario
from mows.sim.simulator import SimulatedDevice
SimulatedDevice(Scenario()).integrate(10)
print(time.perf_counter() - start)
"""


def median_ms(action, repeats: int) -> float:
    """The median wall time of ``repeats`` calls of ``action``, ms."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def first_call_s() -> tuple[float, float]:
    """(import + compile, import + cache load) of the kernel in fresh processes, s."""
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        runs = [
            float(
                subprocess.run(
                    [sys.executable, "-c", _FIRST_CALL], env=env, check=True, capture_output=True, text=True
                ).stdout
            )
            for _ in range(2)
        ]
    return runs[0], runs[1]


def solve_ivp_theta(rhs, state, first_index: int, n_samples: int, sample_rate_hz: float) -> np.ndarray:
    """θ at samples first_index … first_index + n_samples (inclusive) by DOP853 (rtol 1e-10)
    from ``state`` (θ, θ') at the first sample."""
    times = (first_index + np.arange(n_samples + 1)) / sample_rate_hz
    return solve_ivp(rhs, (times[0], times[-1]), state, method="DOP853", rtol=1e-10, atol=1e-13, t_eval=times).y


def solve_ivp_cycle(
    device: SimulatedDevice, amplitude_a: float, first_index: int, excite_s: float = 0.5, ringdown_s: float = 0.5
) -> np.ndarray:
    """θ at the samples of :func:`mows.device.stream.simulated_cycle.simulate_cycle` at θ0 = 0 from
    rest, its excitation switched on at sample ``first_index``, by DOP853 on the device's own
    equation of motion; the excitation ends where the cycle's does, at a drive-current peak
    (:func:`mows.physics.coils.excitation_samples`)."""
    fs = device.sample_rate_hz
    frequency = float(device.expected_frequencies_hz()[0])
    currents = device.scenario.setup.currents_a(0.0, amplitude_a)
    drive = device.equation_of_motion([currents], [frequency], drive_t0_s=first_index / fs)
    n_excite, n_ring = excitation_samples(excite_s, frequency, fs), int(round(ringdown_s * fs))
    excited = solve_ivp_theta(drive, [device.truth.rest_angle_rad[0], 0.0], first_index, n_excite, fs)
    ringing = solve_ivp_theta(device.equation_of_motion(), excited[:, -1], first_index + n_excite, n_ring - 1, fs)
    return np.concatenate([excited[0, :-1], ringing[0]])


def run(repeats: int = 20, first_call: bool = True) -> dict:
    """Figures for ``mows bench`` (milliseconds unless the key says otherwise); ``first_call``
    False leaves out the two fresh-process figures (a compilation alone costs seconds of CPU)."""
    scenario = load_scenario()
    amplitude = scenario.excitation.amplitude_a
    noisy = SimulatedDevice(scenario)
    quiet = SimulatedDevice(scenario.replace(noise=NoiseModel()))
    simulate_cycle(noisy, 0.0, amplitude)  # warm-up
    free = SimulatedDevice(scenario)
    free.pluck(math.radians(23.0))
    figures = {
        "cycle_ms_median": median_ms(lambda: simulate_cycle(noisy, 0.0, amplitude), repeats),
        "cycle_ms_without_noise": median_ms(lambda: simulate_cycle(quiet, 0.0, amplitude), repeats),
        "kernel_ms_per_second_free": median_ms(lambda: free.integrate(int(free.sample_rate_hz)), repeats),
    }
    if first_call:
        figures["first_call_with_compilation_s"], figures["first_call_from_cache_s"] = first_call_s()
    silent = scenario.replace(noise=NoiseModel())
    reference = SimulatedDevice(silent)
    record = simulate_cycle(reference, 0.0, amplitude, SimulatedDevice(silent).expected_frequencies_hz()[0])
    start = time.perf_counter()
    theta_ivp = solve_ivp_cycle(SimulatedDevice(silent), amplitude, record.block.samples.first_sample_index)
    figures["solve_ivp_dop853_ms_per_cycle"] = 1e3 * (time.perf_counter() - start)
    figures["solve_ivp_over_simulator"] = figures["solve_ivp_dop853_ms_per_cycle"] / figures["cycle_ms_without_noise"]
    # With impacts DOP853 steps across the stop's force jumps; in free flight both are exact.
    figures["max_theta_difference_cycle_rad"] = float(np.max(np.abs(record.theta_rad - theta_ivp)))
    plucked = SimulatedDevice(silent)
    plucked.pluck(math.radians(23.0))
    theta_rk4 = plucked.integrate(int(plucked.sample_rate_hz))[0][:, 0]
    theta_free = solve_ivp_theta(
        plucked.equation_of_motion(), [math.radians(23.0), 0.0], 0, len(theta_rk4) - 1, plucked.sample_rate_hz
    )[0]
    figures["max_theta_difference_free_ringdown_rad"] = float(np.max(np.abs(theta_rk4 - theta_free)))
    figures.update(multiprobe_reads(max(3, repeats // 4)))
    return figures


def multiprobe_reads(repeats: int) -> dict:
    """ms to read one second of the three_probes device, driven and free, and of the one-probe
    device, with their ratio (module docstring)."""
    scene = load_scenario("three_probes")
    second = int(scene.sample_rate_hz)
    device = SimulatedDevice(scene)
    tones = plan_probes(device.placed, device.setup, 1.0).group_tones(0)
    device.read(10)  # warm-up
    at_rest = iter([SimulatedDevice(scene) for _ in range(repeats)])  # each driven from rest, within its interval

    def driven():
        fresh = next(at_rest)
        fresh.drive(coil_amplitudes_a(fresh.setup, tones), [t.frequency_hz for t in tones], second)
        fresh.read(second)

    one = SimulatedDevice(load_scenario())
    one.read(10)
    figures = {
        "three_probes_read_ms_per_second_driven": median_ms(driven, repeats),
        "three_probes_read_ms_per_second_free": median_ms(lambda: device.read(second), repeats),
        "one_probe_read_ms_per_second": median_ms(lambda: one.read(second), repeats),
    }
    figures["three_probes_driven_over_one_probe"] = (
        figures["three_probes_read_ms_per_second_driven"] / figures["one_probe_read_ms_per_second"]
    )
    return figures


if __name__ == "__main__":
    for key, value in run().items():
        print(f"{key:34s} {value:.6g}")
