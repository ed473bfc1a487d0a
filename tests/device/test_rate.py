"""The achieved sample rate: samples per host second over a sliding window (mows.device.stream.rate)."""

import pytest

from mows.device.stream.rate import RATE_WINDOW_S, RateMeter


def test_rate_of_a_steady_stream_is_its_samples_per_second():
    meter = RateMeter()
    for i in range(int(2 * RATE_WINDOW_S / 0.1) + 1):  # 100 samples every 0.1 s: 1000 S/s
        meter.add(i * 0.1, 100)
    assert meter.rate_hz(2 * RATE_WINDOW_S) == pytest.approx(1000.0)


def test_rate_is_unknown_in_the_first_window():
    meter = RateMeter()
    meter.add(0.0, 100)
    meter.add(1.0, 100)
    assert meter.rate_hz(1.0) is None
    assert RateMeter().rate_hz(100.0) is None


def test_a_stall_lowers_the_rate():
    meter = RateMeter()
    for i in range(int(RATE_WINDOW_S / 0.1) + 1):
        meter.add(i * 0.1, 100)
    meter.add(RATE_WINDOW_S + 2.0, 100)  # 2 s without samples, then one block
    assert meter.rate_hz(RATE_WINDOW_S + 2.0) < 1000.0 * 0.8
