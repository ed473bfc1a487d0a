"""Ring-down windows cut from a block stream: exact, complete, and honest about gaps."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mows.estimate.ringdown import FitStatus, ProbeLine
from mows.estimate.segments import RingdownWindow, SegmentAssembler, fit_segment
from mows.records.samples import SampleBlock


def line_of(window: RingdownWindow) -> ProbeLine:
    """The window's one probe, at its θ0, looked for at its tone."""
    return ProbeLine(0, window.theta0_rad, window.excitation_frequency_hz)


FS = 20_000.0
EPOCH_NS = 1_700_000_000 * 10**9  # device clock: ns since its epoch
NS_PER_SAMPLE = 50_000  # at FS


def stream(n=40_000, seed=0):
    samples = np.random.default_rng(seed).standard_normal((n, 2))
    return samples, np.zeros((n, 2), bool)


def blocks(samples, saturated, sizes, start_index=1000):
    index = 0
    while index < len(samples):
        size = sizes[index % len(sizes)] if isinstance(sizes, list) else sizes
        yield SampleBlock(
            start_index + index,
            EPOCH_NS + (start_index + index) * NS_PER_SAMPLE,
            FS,
            samples[index : index + size],
            saturated[index : index + size],
        )
        index += size


def window_at(index, n, start_index=1000, **kw):
    return RingdownWindow(start_ns=EPOCH_NS + (start_index + index) * NS_PER_SAMPLE, duration_s=n / FS, **kw)


@settings(max_examples=60, deadline=None)
@given(
    sizes=st.lists(st.integers(200, 1000), min_size=1, max_size=5),
    start=st.integers(0, 20_000),
    length=st.integers(1000, 10_000),
    announce_after=st.integers(0, 40),
)
def test_any_block_split_gives_the_exact_window(sizes, start, length, announce_after):
    samples, saturated = stream()
    assembler = SegmentAssembler(buffer_s=2.0)
    got, announced = [], False
    for k, block in enumerate(blocks(samples, saturated, sizes)):
        if k == announce_after:
            got += assembler.announce(window_at(start, length))
            announced = True
        got += assembler.add_block(block)
    if not announced:  # announce_after past the last block: every sample is here already
        got += assembler.announce(window_at(start, length))
    assert len(got) == 1
    segment = got[0]
    assert segment.missing_samples == 0
    np.testing.assert_array_equal(segment.samples_t, samples[start : start + length])
    assert segment.first_sample_index == 1000 + start


def test_a_sequence_gap_is_counted_and_refused():
    samples, saturated = stream()
    assembler = SegmentAssembler()
    assembler.announce(window_at(1000, 10_000, theta0_rad=0.3, excitation_frequency_hz=112.0))
    got = []
    for block in blocks(samples, saturated, 500):
        if block.first_sample_index == 1000 + 5000:
            continue  # one block lost on the way
        got += assembler.add_block(block)
    assert assembler.missing_samples == 500
    assert got[0].missing_samples == 500
    (fit,) = fit_segment(got[0], [line_of(got[0].window)])
    assert fit.status == FitStatus.DATA_GAP and "500" in fit.message


def test_each_run_of_lost_blocks_is_one_gap():
    samples, saturated = stream()
    assembler = SegmentAssembler()
    lost = {1000 + 5000, 1000 + 20_000, 1000 + 20_500}  # one block, then a run of two
    for block in blocks(samples, saturated, 500):
        if block.first_sample_index not in lost:
            assembler.add_block(block)
    assert assembler.gaps == 2 and assembler.missing_samples == 1500
    assert assembler.blocks == 40_000 // 500 - 3


def test_a_window_announced_after_its_samples_left_the_buffer():
    samples, saturated = stream()
    assembler = SegmentAssembler(buffer_s=0.2)
    for block in blocks(samples, saturated, 500):
        assembler.add_block(block)
    late = assembler.announce(window_at(100, 2000))
    assert late and late[0].missing_samples == 2000 and assembler.late_windows == 1


@pytest.mark.parametrize("heard", ["before the first block", "after it"])
def test_ringdowns_over_before_listening_began_are_counted_not_answered(heard):
    """A late listener hears the announcements the driver kept (transient local): those of
    ring-downs over before its first block, or on an earlier clock, are not its to fit; one that
    overlaps the first block is answered, with the samples it never had counted missing."""
    samples, saturated = stream()
    stream_start = 1000 + 4000  # the listener's first block: 4000 samples into the device's stream
    kept = [
        window_at(0, 2000, cycle_id=1),  # over 2000 samples before listening began
        window_at(2000, 2000, cycle_id=2),  # ends exactly where it began
        dataclasses.replace(window_at(6000, 2000, cycle_id=3), device_epoch=-1),  # an earlier clock
        window_at(3000, 2000, cycle_id=4),  # half before, half after
        window_at(6000, 2000, cycle_id=5),  # wholly heard
    ]
    assembler = SegmentAssembler()
    got = []
    if heard == "before the first block":
        for window in kept:
            got += assembler.announce(window)
    for block in blocks(samples[4000:], saturated[4000:], 500, start_index=stream_start):
        got += assembler.add_block(block)
        if heard == "after it" and assembler.blocks == 1:
            for window in kept:
                got += assembler.announce(window)
    assert [s.window.cycle_id for s in got] == [4, 5]
    assert [s.missing_samples for s in got] == [1000, 0]
    assert assembler.windows_before_start == 3


def test_duplicates_are_ignored_and_rate_changes_restart_the_buffer():
    samples, saturated = stream(4000)
    assembler = SegmentAssembler()
    first, second = list(blocks(samples, saturated, 2000))
    assembler.add_block(first)
    assembler.add_block(first)
    assembler.add_block(second)
    assert assembler.blocks == 2 and assembler.missing_samples == 0
    faster = SampleBlock(5000, EPOCH_NS + 10**9, 2 * FS, samples[:100], saturated[:100])
    assembler.add_block(faster)
    assert assembler.rate_changes == 1


def test_saturation_flags_travel_with_the_samples():
    samples, saturated = stream(20_000)
    saturated[3000:3100, 1] = True
    assembler = SegmentAssembler()
    assembler.announce(window_at(2000, 5000))
    got = [s for b in blocks(samples, saturated, 400) for s in assembler.add_block(b)]
    assert got[0].saturated[1000:1100, 1].all() and got[0].saturated.sum() == 100


def test_bad_buffer_length_is_an_error():
    with pytest.raises(ValueError, match="buffer_s"):
        SegmentAssembler(buffer_s=0.0)


def restarted(blocks_of_a_clock, epoch):
    """The same stream from a device whose clock started again: indices and stamps from 0."""
    return [
        SampleBlock(
            b.first_sample_index - 1000,
            b.stamp_ns - EPOCH_NS - 1000 * NS_PER_SAMPLE,
            FS,
            b.samples_t,
            b.saturated,
            epoch=epoch,
        )
        for b in blocks_of_a_clock
    ]


def test_a_restarted_device_clock_starts_the_stream_again():
    """After a restart the indices run from 0 again: without the epoch every block would look
    like a repeat and be dropped. A window of the old clock that was still waiting is returned
    with its samples missing (refused as a gap, not fitted on another clock's samples); one of
    the new clock is cut from the new clock's blocks."""
    samples, saturated = stream(8000)
    assembler = SegmentAssembler()
    old = list(blocks(samples[:4000], saturated[:4000], 500))
    for block in old[:4]:
        assembler.add_block(block)
    assert assembler.announce(window_at(1500, 1000)) == []  # waits for samples up to 2500
    new = restarted(list(blocks(samples[4000:], saturated[4000:], 500)), epoch=1)
    lost = assembler.add_block(new[0])
    assert len(lost) == 1 and lost[0].window.start_ns == window_at(1500, 1000).start_ns
    assert (
        fit_segment(lost[0], [line_of(lost[0].window)])[0].status == FitStatus.DATA_GAP
        and assembler.device_restarts == 1
    )
    # A window of the new clock (its stamps start at 0): the new blocks' samples, exact.
    window = RingdownWindow(start_ns=200 * NS_PER_SAMPLE, duration_s=1000 / FS, device_epoch=1)
    done = assembler.announce(window)
    for block in new[1:]:
        done += assembler.add_block(block)
    assert len(done) == 1 and done[0].missing_samples == 0
    np.testing.assert_array_equal(done[0].samples_t, samples[4200:5200])
    # An announcement of the old clock that arrives late is refused at once.
    (stale,) = assembler.announce(window_at(3000, 500))
    assert stale.missing_samples and fit_segment(stale, [line_of(stale.window)])[0].status == FitStatus.DATA_GAP
