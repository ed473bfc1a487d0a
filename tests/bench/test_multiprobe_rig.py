"""Cycles of several probes in device time: excited together, cut at the switch-off, fitted jointly.

Requirement: one cycle of the three_probes scene excites all three probes in one group (their
summed drive within the cap), cuts the ring-down window the driver announces and yields one
RingdownFit per probe, carrying its probe id, at that probe's coupled frequency; a window with
samples missing is refused for every probe, not patched.
"""

import numpy as np

from mows.bench.rig import ONE_ROUND, DeviceTimeRig
from mows.device.cycle.phases import CycleRequest
from mows.estimate.probe_set import probe_lines
from mows.estimate.ringdown.types import FitStatus
from mows.estimate.segments import RingdownWindow, Segment, fit_segment
from mows.sim.scenario import load_scenario

SCENE = load_scenario("three_probes")


def test_one_cycle_fits_every_probe_jointly_with_its_id():
    rig = DeviceTimeRig(SCENE, ONE_ROUND, seed=3)
    cycle = rig.run_cycle(CycleRequest(0.0))
    assert cycle.outcome.refused_probes == ()
    assert [f.probe_id for f in cycle.fits] == [0, 1, 2]
    assert 0.0 < rig.peak_current_a <= SCENE.setup.cap.limit_a
    coupled = rig.device.device.expected_frequencies_hz()
    alone = [p.probe.f00_hz for p in rig.device.device.placed]
    for fit, expected, f00 in zip(cycle.fits, coupled, alone):
        assert fit.ok, fit.message
        assert fit.frequency_std_hz < 5e-3  # 0.1 to 2.2 mHz measured
        # Each line is its own probe's: within the swing's few mHz of its coupled frequency,
        # 12.5 Hz from the others'.
        assert abs(fit.frequency_hz - expected) < 0.02, (fit.frequency_hz, expected, f00)


def test_a_window_with_missing_samples_is_refused_for_every_probe():
    rig = DeviceTimeRig(SCENE, ONE_ROUND)
    lines = probe_lines(SCENE.sensors.pair, rig.device.device.placed, [0, 1, 2], [100.0, 112.5, 125.0])
    samples = np.zeros((1000, 2))
    segment = Segment(RingdownWindow(0, 0.05), 0, 20_000.0, samples, np.zeros((1000, 2), bool), missing_samples=7)
    fits = fit_segment(segment, lines)
    assert [f.probe_id for f in fits] == [0, 1, 2]
    assert all(f.status is FitStatus.DATA_GAP and "7 of 1000" in f.message for f in fits)
