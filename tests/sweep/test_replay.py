"""A recording's cycles cut into the sweeps the mapper published (:mod:`mows.sweep.replay`).

Requirement: a recorded sweep holds the cycles it names, and cycles before or between sweeps are
in none; cycles after the last recorded sweep (one the recording stopped in, or a bag without
sweeps) are apart, one more. A recording whose sweeps name no cycles (an older one) is cut by
stamps: a sweep holds the cycles whose last ring-down began no later than its stamp (that of its
last ring-down's fit); a recorded sweep with no cycle of its own adds none."""

from mows.sweep.replay import RecordedCycle, RecordedSession

NS = 1_000_000_000


def cycles(*seconds):
    return tuple(RecordedCycle(k, 0.1 * k, 2, round(s * NS)) for k, s in enumerate(seconds, start=1))


def ids(groups):
    return [[c.cycle_id for c in group] for group in groups]


def test_a_bag_without_sweeps_is_one_sweep_and_a_sweep_without_cycles_adds_none():
    bare = RecordedSession(cycles(1, 2, 3), (), ())
    assert ids(bare.sweeps()) == [] and ids([bare.after_last()]) == [[1, 2, 3]]
    assert ids(RecordedSession(cycles(5, 6), (), (round(1.0 * NS), round(6.003 * NS))).sweeps()) == [[1, 2]]


def named(ids_per_sweep, *seconds):
    return RecordedSession(cycles(*seconds), (), (), tuple(tuple(ids) for ids in ids_per_sweep))


def test_a_recorded_sweep_is_the_cycles_it_names_and_others_before_it_are_left_out():
    """Cycles another client ran before a sweep (1, 2), and a cancelled sweep's between two
    (5), are in no sweep: the mapper did not take them."""
    session = named([(3, 4, 6), (7, 8)], 1, 2, 3, 4, 5, 6, 7, 8)
    assert ids(session.sweeps()) == [[3, 4, 6], [7, 8]]
    assert ids([session.after_last()]) == [[]] and ids([session.left_out()]) == [[1, 2, 5]]


def test_cycles_after_the_last_named_sweep_are_one_more_apart_from_it():
    session = named([(1, 2, 3)], 1, 2, 3, 4, 5)
    assert ids(session.sweeps()) == [[1, 2, 3]] and ids([session.after_last()]) == [[4, 5]]
    assert session.left_out() == ()


def test_a_recording_without_named_cycles_is_cut_by_stamps():
    session = RecordedSession(cycles(1, 2, 3, 11, 12, 21), (), (round(3.003 * NS), round(12.003 * NS)))
    assert ids(session.sweeps()) == [[1, 2, 3], [4, 5]] and ids([session.after_last()]) == [[6]]
