"""The estimator's flow without ROS (mows.estimate.stream): messages as the estimator node gets
them (here plain objects with the same fields) in, a fit, an estimate along the axis and the f00
calibration's progress out."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from mows.bench.estimator import FREQUENCY_HZ, N_SAMPLES, SAMPLE_RATE_HZ, RingdownCase
from mows.estimate.probe_set import ProbeEntry
from mows.estimate.ringdown import FitOptions, FitStatus
from mows.estimate.stream import FitSettings, RingdownEstimator
from mows.physics.probe import PAPER_PROBE

START_NS = 1_763_000_000 * 10**9  # the device clock at the first sample
NS_PER_SAMPLE = round(1e9 / SAMPLE_RATE_HZ)
BLOCK = 500
F00_HZ = 112.0


def stamp(ns: int):
    return SimpleNamespace(sec=ns // 10**9, nanosec=ns % 10**9)


def block_msg(sequence: int, samples: np.ndarray):
    """A MagnetometerBlock of ``samples`` on channel 1 and zeros on channel 2 (their difference
    is the signal)."""
    first = sequence * BLOCK
    channels = [
        SimpleNamespace(field_t=column, saturated=np.zeros(len(column), bool))
        for column in (samples, np.zeros_like(samples))
    ]
    return SimpleNamespace(
        header=SimpleNamespace(stamp=stamp(START_NS + first * NS_PER_SAMPLE)),
        first_sample_index=first,
        sample_rate_hz=SAMPLE_RATE_HZ,
        sequence=sequence,
        channels=channels,
    )


def ringdown_msg(cycle_id: int, first: int = 0, duration_s: float = N_SAMPLES / SAMPLE_RATE_HZ):
    """The ExcitationState that announces a ring-down starting at sample ``first``."""
    return SimpleNamespace(
        header=SimpleNamespace(stamp=stamp(START_NS + first * NS_PER_SAMPLE)),
        planned_duration_s=duration_s,
        cycle_id=cycle_id,
        repeat_index=0,
        theta0_rad=0.0,
        frequency_hz=FREQUENCY_HZ,
        tuning=False,
        phase=3,
        PHASE_RINGDOWN=3,
    )


def paper_lines(held):
    """The lines of the paper's single-term pickup (Eq. S11) at each probe's θ0 and tone."""
    return [p.entry.line(p.theta0_rad, None, "difference", p.tone_hz) for p in held]


def settings(lines=paper_lines, f00_hz=F00_HZ):
    return FitSettings((ProbeEntry(0, PAPER_PROBE, f00_hz),), lines, FitOptions(), coil_off_skip_s=0.0)


def ringdown(estimator, k, lines=paper_lines):
    """Announce the ``k``-th ring-down of the stream (cycle k + 1), then stream its samples
    (noise drawn with seed k); what the estimator returns."""
    case = RingdownCase(0.0, snr_db=40.0)
    samples = case.draw(np.random.default_rng(k))
    per_ringdown = N_SAMPLES // BLOCK
    segments = estimator.announce(ringdown_msg(k + 1, first=k * N_SAMPLES))
    for j in range(per_ringdown):
        segments += estimator.add_block(block_msg(k * per_ringdown + j, samples[j * BLOCK : (j + 1) * BLOCK]))
    assert len(segments) == 1
    (estimated,) = estimator.estimate(segments[0], settings(lines))
    return estimated, case


def test_a_streamed_ringdown_is_fitted_and_inverted_along_the_axis():
    estimator = RingdownEstimator(buffer_s=5.0)
    estimated, case = ringdown(estimator, 0)
    assert estimated.fit.ok, estimated.fit.report()
    assert estimated.window.cycle_id == 1 and not estimated.calibrated
    # Unbiased within the Cramér–Rao bound (5 σ), and the shift is f − f00 (Eq. 6's Δf).
    assert abs(estimated.fit.frequency_hz - FREQUENCY_HZ) < 5 * case.crb_hz()
    assert estimated.estimate.ok
    assert estimated.estimate.frequency_shift_hz == pytest.approx(estimated.fit.frequency_hz - F00_HZ, abs=1e-12)
    # Δf > 0: the field along x' stiffens the spring (positive B_x').
    assert estimated.estimate.field_along_axis_t > 0
    assert estimator.last == f"probe 0: {estimated.fit.report()}"


def test_a_model_that_cannot_be_built_is_a_failed_fit_not_an_exception():
    def no_model(held):
        raise ValueError("sensing axis (0, 0)")

    estimated, _ = ringdown(RingdownEstimator(buffer_s=5.0), 0, lines=no_model)
    assert estimated.fit.status is FitStatus.BAD_FIT and "sensing axis (0, 0)" in estimated.fit.message
    assert not estimated.estimate.ok and math.isnan(estimated.estimate.field_along_axis_t)


def test_malformed_messages_are_refused_and_leave_nothing_behind():
    estimator = RingdownEstimator(buffer_s=5.0)
    no_channels = block_msg(0, np.zeros(BLOCK))
    no_channels.channels = []
    with pytest.raises(ValueError, match="without channels"):
        estimator.add_block(no_channels)
    with pytest.raises(ValueError, match="not a window"):
        estimator.announce(ringdown_msg(1, duration_s=math.nan))
    assert estimator.assembler.blocks == 0


def test_a_calibration_takes_the_next_ok_ringdowns_and_one_at_a_time():
    estimator = RingdownEstimator(buffer_s=5.0)
    # In zero field f = f00 (Eq. 6), so the calibrated f00 is the mean fitted frequency.
    calibration = estimator.begin_calibration(settings(), 0.0, 3, 10.0)
    with pytest.raises(ValueError, match="already running"):
        estimator.begin_calibration(settings(), 0.0, 3, 10.0)
    results = [ringdown(estimator, k)[0] for k in range(3)]
    assert [r.calibrated for r in results] == [False, False, True]
    outcome = calibration.outcome
    assert outcome.ok and outcome.n_used == 3
    assert outcome.f00_hz == pytest.approx(np.mean([r.fit.frequency_hz for r in results]), abs=1e-9)
    assert abs(outcome.f00_hz - FREQUENCY_HZ) < 5 * outcome.f00_std_hz
    estimator.end_calibration()
    assert not ringdown(estimator, 3)[0].calibrated  # nobody is calibrating any more
    estimator.begin_calibration(settings(), 0.0, 1, 10.0)  # and a new one may start


def test_a_failed_ringdown_is_not_offered_to_the_calibration():
    estimator = RingdownEstimator(buffer_s=5.0)
    calibration = estimator.begin_calibration(settings(), 0.0, 1, 10.0)

    def no_model(held):
        raise ValueError("no model")

    assert not ringdown(estimator, 0, lines=no_model)[0].calibrated
    assert not calibration.done
    assert ringdown(estimator, 1)[0].calibrated and calibration.outcome.ok


def phase_msg(phase: int, at: int):
    """An ExcitationState of another phase (IDLE 0, GAP 4, FAULT 5) beginning at sample ``at``."""
    return SimpleNamespace(
        header=SimpleNamespace(stamp=stamp(START_NS + at * NS_PER_SAMPLE)), phase=phase, PHASE_RINGDOWN=3
    )


@pytest.mark.parametrize("phase, at_s, cut", [(0, 0.3, True), (5, 0.3, True), (4, None, False), (0, None, False)])
def test_a_ring_down_its_cycle_ended_inside_is_no_measurement(phase, at_s, cut):
    """A cycle cancelled (IDLE) or aborted (FAULT) 0.3 s into its ring-down: the driver does not
    count that ring-down as recorded, so no OK fit of it is published (TOO_SHORT, saying why),
    though the samples of its whole window come. The next phase at the window's end (a GAP, the
    cycle's IDLE) cuts nothing."""
    estimator = RingdownEstimator(buffer_s=5.0)
    samples = RingdownCase(0.0, snr_db=40.0).draw(np.random.default_rng(0))
    at = N_SAMPLES if at_s is None else round(at_s * SAMPLE_RATE_HZ)
    segments = estimator.announce(ringdown_msg(1))
    for j in range(N_SAMPLES // BLOCK):
        segments += estimator.add_block(block_msg(j, samples[j * BLOCK : (j + 1) * BLOCK]))
        if (j + 1) * BLOCK == min(at, N_SAMPLES - BLOCK):  # heard before the window's last block
            assert segments == []
            segments += estimator.announce(phase_msg(phase, at))
    (segment,) = segments
    (estimated,) = estimator.estimate(segment, settings())
    assert estimated.fit.ok is not cut and segment.cut_short is cut, estimated.fit.report()
    if cut:
        assert estimated.fit.status is FitStatus.TOO_SHORT and "cut short after 0.30 s" in estimated.fit.message
        assert len(segment.samples_t) == at and not estimated.estimate.ok
