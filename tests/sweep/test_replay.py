"""A recording's cycles cut into the sweeps the mapper published (:mod:`mows.sweep.replay`).

Requirement: a sweep holds the cycles whose last ring-down began no later than the sweep's stamp
(the stamp of its last ring-down's fit, a few ms after that ring-down began); cycles after the
last recorded sweep (one the recording stopped in, or a bag without sweeps) are one more sweep;
a recorded sweep with no cycle of its own adds none."""

from mows.sweep.replay import RecordedCycle, RecordedSession

NS = 1_000_000_000


def cycles(*seconds):
    return tuple(RecordedCycle(k, 0.1 * k, 2, round(s * NS)) for k, s in enumerate(seconds, start=1))


def ids(groups):
    return [[c.cycle_id for c in group] for group in groups]


def test_cycles_are_cut_at_each_recorded_sweep_and_the_rest_is_one_more():
    session = RecordedSession(cycles(1, 2, 3, 11, 12, 21), (), (round(3.003 * NS), round(12.003 * NS)))
    assert ids(session.sweeps()) == [[1, 2, 3], [4, 5], [6]]


def test_a_bag_without_sweeps_is_one_sweep_and_a_sweep_without_cycles_adds_none():
    assert ids(RecordedSession(cycles(1, 2, 3), (), ()).sweeps()) == [[1, 2, 3]]
    assert ids(RecordedSession(cycles(5, 6), (), (round(1.0 * NS), round(6.003 * NS))).sweeps()) == [[1, 2]]
