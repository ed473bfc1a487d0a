"""Groups of a multi-tone plan excited in turn: the duty limit and the emergency stop hold for the sum.

Requirements: a group's summed drive occupies the coils once, so that its tones together
count one excitation's time against the duty limit, and no window of the device clock (every
one, counted by brute force from the summed currents) is on for more than the limit allows;
the summed current never exceeds the cap; an emergency stop switches every coil off at its
sample and nothing more is excited.
"""

import numpy as np
import pytest

from mows.device.cycle.duty import DutyCycleLimit
from mows.device.cycle.tone_groups import GroupSequence
from mows.physics.coils import largest_spacing
from mows.physics.multitone import Tone, plan_excitation

SETUP = largest_spacing()
RATE_HZ = 2_000.0
# Four 5 A tones at θ0 = 0.3 rad, 4.42 A each on coil 2: two fit the 10 A cap together.
TONES = [Tone(k, f, 0.3, 5.0, 1.8) for k, f in enumerate((100.0, 112.0, 125.0, 140.0))]


def coils_on(sequence, n_samples):
    """Samples with any coil's summed current on: the excitations' intervals, taken from the
    waveform (a sine starts at zero, so its first sample is counted from the interval)."""
    on = np.zeros(n_samples, bool)
    for e in sequence.excitations:
        on[e.on_index : e.off_index] = True
    currents = sequence.currents_a(np.arange(n_samples))
    assert np.all(np.any(currents != 0.0, axis=1) <= on)  # no current outside an excitation
    return on


def test_groups_keep_the_duty_limit_and_the_cap():
    plan = plan_excitation(SETUP, TONES, 0.5)
    assert len(plan.groups) == 2 and [len(g) for g in plan.groups] == [2, 2]
    window = int(2.0 * RATE_HZ)
    duty = DutyCycleLimit(0.3, window)  # 0.6 s of every 2 s: one 0.5 s excitation per window
    sequence = GroupSequence(plan, SETUP, duty, RATE_HZ)
    first = sequence.next(0)
    sequence.switched(first.on_index, first.off_index)
    # Two tones summed are one excitation's time, not two.
    assert duty.fraction(first.off_index) == pytest.approx(sequence.excite_samples / window)
    second = sequence.next(first.off_index)
    sequence.switched(second.on_index, second.off_index)
    assert sequence.next(second.off_index) is None and sequence.done
    # Delayed, not shortened: until the window that ends with it holds the first excitation's
    # last (budget − excitation) samples and its own, W − budget samples after the first ended.
    assert second.on_index == first.off_index + window - duty.budget_samples
    assert second.off_index - second.on_index == first.off_index - first.on_index == int(0.5 * RATE_HZ)
    total = second.off_index + window
    on = coils_on(sequence, total)
    assert np.convolve(on, np.ones(window, int), "full").max() <= 0.3 * window  # every window
    assert np.abs(sequence.currents_a(np.arange(total))).max() <= SETUP.cap.limit_a
    assert [e.probe_ids for e in sequence.excitations] == list(plan.groups)


def test_an_emergency_stop_switches_every_tone_off_and_latches():
    plan = plan_excitation(SETUP, TONES, 0.5)
    duty = DutyCycleLimit(1.0, int(RATE_HZ))
    sequence = GroupSequence(plan, SETUP, duty, RATE_HZ)
    first = sequence.next(0)
    stop = first.on_index + 301
    before = sequence.currents_a(np.arange(first.on_index, stop))
    assert np.abs(before).max() > 1.0  # the summed drive was on
    sequence.emergency_stop(stop, "emergency stop pressed")
    assert np.all(sequence.currents_a(np.arange(stop, first.off_index + 10)) == 0.0)
    assert duty.fraction(stop) == pytest.approx(301 / RATE_HZ)  # the time the coils were on, counted
    assert sequence.next(first.off_index) is None and sequence.stop_reason == "emergency stop pressed"
    assert len(sequence.excitations) == 1


def test_a_group_that_could_never_keep_the_duty_limit_is_refused():
    plan = plan_excitation(SETUP, TONES[:1], 0.5)
    with pytest.raises(ValueError, match="duty-cycle limit"):
        GroupSequence(plan, SETUP, DutyCycleLimit(0.1, int(RATE_HZ)), RATE_HZ)
