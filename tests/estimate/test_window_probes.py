"""Which probes a ring-down window holds, and at which θ0 each is fitted.

Requirement: a window whose excitation lists its probes (a group of a multi-tone drive) is
fitted over exactly those, each at its own orientation (its pickup at that θ0, and its fit's
``theta0_rad`` its own) and looked for at its tone; a listed id the estimator's ``probes`` do
not know gets a failed fit naming it and no number; a window that lists nothing holds every
probe at the window's θ0. The signal here is the paper's single-term pickup (Eq. S11), whose
2θ0-dependence makes a probe fitted at the wrong θ0 fail: a sin θ0 pickup at 75° and at 0° differ
by the carrier's whole first harmonic.
"""

import math

import numpy as np
import pytest

from mows.estimate.probe_set import read_probe_set, window_probes
from mows.estimate.ringdown import FitOptions, FitStatus
from mows.estimate.segments import RingdownWindow, Segment, window_from_message
from mows.estimate.stream import FitSettings, RingdownEstimator
from mows.physics.fluxgate import FluxgatePair, pickup_harmonics
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE
from mows.physics.signal import signal_t

FS = 20_000.0
PROBES = read_probe_set("{0: 112.5, 1: 125.0, 2: 101.0}", PAPER_PROBE, lambda path: PAPER_PROBE)
THETA0 = {0: 0.2, 1: math.radians(75.0), 2: 1.6, 7: -0.5, 9: 2.5}
TONE_HZ = {0: 112.55, 1: 125.05, 2: 101.05, 7: 90.0, 9: 140.0}  # the driver's tones  # each probe's own orientation


def window(ids=(), tones=None, **kw):
    tones = [TONE_HZ[k] for k in ids] if tones is None else tones
    return RingdownWindow(
        0, 0.5, 1, 0, 0.1, 112.5, False, tuple(ids), tuple(tones), tuple(THETA0[k] for k in ids), **kw
    )


def test_a_window_that_lists_probes_holds_those_at_their_own_theta0_and_tone():
    held = window_probes(PROBES, window((2, 7, 0)))
    assert [p.probe_id for p in held] == [0, 2, 7]
    assert held[0].entry is PROBES[0] and held[1].entry is PROBES[2] and held[2].entry is None
    assert held[1].theta0_rad == THETA0[2] and held[1].tone_hz == TONE_HZ[2]
    assert "probe 7" in held[2].unknown_message(PROBES) and "0, 1, 2" in held[2].unknown_message(PROBES)


def test_a_window_that_lists_none_holds_every_probe_at_the_windows_theta0():
    held = window_probes(PROBES, RingdownWindow(0, 0.5, theta0_rad=0.4))
    assert [(p.probe_id, p.theta0_rad, p.entry) for p in held] == [(e.probe_id, 0.4, e) for e in PROBES]
    assert all(math.isnan(p.tone_hz) for p in held)


def test_a_line_takes_its_own_theta0s_pickup_and_its_tone():
    pair = FluxgatePair.paper()
    line = PROBES[1].line(THETA0[1], pair, "difference", 125.3)
    own = pickup_harmonics(pair, Pose(theta0_rad=THETA0[1]), PAPER_PROBE.lever_m, PAPER_PROBE.moment_am2)
    at_stage = pickup_harmonics(pair, Pose(theta0_rad=0.1), PAPER_PROBE.lever_m, PAPER_PROBE.moment_am2)
    assert line.theta0_rad == THETA0[1] and line.expected_frequency_hz == 125.3
    assert np.allclose(line.pickup, own) and not np.allclose(line.pickup, at_stage, rtol=0.1)
    assert PROBES[1].line(0.0, None, "difference", math.nan).expected_frequency_hz == 125.0  # no tone: f00


@pytest.mark.parametrize(
    "kw, named",
    [
        (dict(probe_ids=(0, 1), probe_frequency_hz=(112.5,), probe_theta0_rad=(0.0, 0.1)), "1 tones"),
        (dict(probe_ids=(1, 1), probe_frequency_hz=(1.0, 2.0), probe_theta0_rad=(0.0, 0.1)), "an id twice"),
        (dict(probe_ids=(1,), probe_frequency_hz=(1.0,), probe_theta0_rad=(math.nan,)), "not all finite"),
    ],
)
def test_a_window_whose_probe_lists_disagree_is_refused_naming_them(kw, named):
    with pytest.raises(ValueError, match=named):
        RingdownWindow(0, 0.5, 3, **kw)


class Earlier:
    """An ExcitationState recorded before it listed probes."""

    class header:
        class stamp:
            sec, nanosec = 1, 5

    planned_duration_s, cycle_id, repeat_index, theta0_rad, frequency_hz, tuning = 0.5, 2, 0, 0.3, 112.5, False


def test_an_announcement_without_probe_lists_is_a_window_of_none():
    w = window_from_message(Earlier)
    assert w.probe_ids == () and w.theta0_rad == 0.3 and w.start_ns == 1_000_000_005


def samples(*probes):
    """Two channels of the paper's pickup of each (id, f) at its own θ0, plus noise."""
    t = np.arange(10_000) / FS
    one = sum(signal_t(t, THETA0[k], 0.3, f, 0.4 + k, 1.8, 2e-7) for k, f in probes)
    return np.column_stack([2 * one, one]) + 1e-10 * np.random.default_rng(4).standard_normal((t.size, 2))


def settings():
    def lines(held):
        return [p.entry.line(p.theta0_rad, None, "difference", p.tone_hz) for p in held]

    return FitSettings(PROBES, lines, FitOptions(), 0.0)


def test_a_group_is_fitted_over_its_probes_each_at_its_own_theta0_and_an_unknown_id_is_reported():
    data = samples((1, 125.08), (2, 101.04))
    segment = Segment(window((1, 2, 9)), 0, FS, data, np.zeros(data.shape, bool), 0)
    one, two, nine = RingdownEstimator(5.0).estimate(segment, settings())
    for e, k, f_true in ((one, 1, 125.08), (two, 2, 101.04)):
        assert e.fit.ok and e.probe_id == k and not e.unknown_probe, e.fit.message
        assert e.fit.theta0_rad == THETA0[k] and abs(e.fit.frequency_hz - f_true) < 4 * e.fit.frequency_std_hz
        assert e.estimate.frequency_shift_hz == pytest.approx(e.fit.frequency_hz - PROBES[k].f00_hz)
    assert nine.probe_id == 9 and nine.unknown_probe and nine.fit.status == FitStatus.BAD_FIT
    assert "probe 9" in nine.fit.message and "probe 9" in nine.report()
    assert math.isnan(nine.fit.frequency_hz) and math.isnan(nine.estimate.field_along_axis_t)


def test_fitted_at_the_windows_one_theta0_the_same_group_is_not_at_its_frequencies():
    """The control: the lines at the stage's θ0 instead of each probe's own miss the signal."""
    data = samples((1, 125.08), (2, 101.04))
    stage_only = RingdownWindow(0, 0.5, 1, 0, 0.1, 112.5)
    only_listed = read_probe_set("{1: 125.0, 2: 101.0}", PAPER_PROBE, lambda path: PAPER_PROBE)

    def lines(held):
        return [p.entry.line(p.theta0_rad, None, "difference") for p in held]

    fitted = RingdownEstimator(5.0).estimate(
        Segment(stage_only, 0, FS, data, np.zeros(data.shape, bool), 0),
        FitSettings(only_listed, lines, FitOptions(), 0.0),
    )
    assert not all(e.fit.ok for e in fitted) or any(
        abs(e.fit.frequency_hz - f) > 4 * e.fit.frequency_std_hz for e, f in zip(fitted, (125.08, 101.04))
    )
