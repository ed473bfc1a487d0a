"""The estimator's ``probes`` text: each form read into its probe, every bad entry refused in
one line naming it, and an empty text leaving the single-probe estimator as it is."""

import numpy as np
import pytest

from mows.estimate.probe_set import own_probe_entry, read_probe_set, with_f00
from mows.estimate.ringdown import FitOptions
from mows.estimate.segments import RingdownWindow, Segment
from mows.estimate.settings import FitParameters, node_probes
from mows.estimate.stream import FitSettings, RingdownEstimator
from mows.physics.fluxgate import FluxgatePair, pickup_harmonics
from mows.physics.multitone import MAX_PROBES
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE, Probe
from mows.physics.signal import signal_t

OTHER = PAPER_PROBE.replace(spring_nm_per_rad=PAPER_PROBE.spring_nm_per_rad * 1.2)


def read(text):
    return read_probe_set(text, PAPER_PROBE, lambda path: {"b.yaml": OTHER}[path])


def test_each_form_gives_its_probe_in_order_of_id():
    entries = read("{2: {f00_hz: 100.5, f00_std_hz: 0.001, position_m: [0, 0.05, 0]}, 0: 112.5, 1: b.yaml}")
    assert [e.probe_id for e in entries] == [0, 1, 2]
    assert entries[0].f00_hz == 112.5 and entries[0].probe.f00_hz == pytest.approx(112.5, abs=1e-9)
    assert entries[0].probe.replace(spring_nm_per_rad=PAPER_PROBE.spring_nm_per_rad) == PAPER_PROBE
    assert entries[1].probe is OTHER and entries[1].f00_hz == OTHER.f00_hz
    assert entries[2].f00_std_hz == 0.001 and entries[2].position_m == (0.0, 0.05, 0.0)
    assert read("") == () and read("  ") == ()


def test_numbers_read_as_yaml_1_2_and_places_given_only_where_stated():
    entries = read("{0: 1.125e2, 1: {f00_hz: 125, position_m: [0, 1e-2, 0]}}")
    assert entries[0].f00_hz == 112.5 and entries[1].position_m == (0.0, 0.01, 0.0)
    # Probes without a place share the single probe's: no spacing to keep between them.
    assert [e.position_m for e in read("{0: 112.5, 1: 125}")] == [(0.0, 0.0, 0.0)] * 2
    with pytest.raises(ValueError, match=r"^probes\[0\]: probe file 1.125e2 does not exist$"):
        read_probe_set('{0: "1.125e2"}', PAPER_PROBE, Probe.from_yaml)  # quoted: text, a file's name


@pytest.mark.parametrize(
    "text, named",
    [
        ("[112.5, 125]", "not a mapping"),
        ("{0: 112.5, 0.5: 125}", "probe id 0.5"),
        ("{0: 112.5, 256: 125}", "probe id 256"),
        ("{0: 112.5, 1: 112.9}", "probes 0 and 1"),
        ("{0: -3}", "f00_hz = -3"),
        ("{0: .nan}", "f00_hz = nan"),
        ("{0: {f00_hz: 112.5, lever: 2}}", "probes[0] = {'f00_hz': 112.5, 'lever': 2} is not an f00"),
        ("{0: {f00_hz: 112.5, position_m: [0, 1]}}", "probes[0].position_m = [0, 1] must be a finite 3-vector"),
        ("{0: {f00_hz: 112.5, position_m: [0, .nan, 0]}}", "probes[0].position_m = [0, nan, 0] must be a finite"),
        ("{a: 112.5}", "probe id 'a' is not an integer"),
        ("{true: 112.5}", "probe id True is not an integer"),
        (
            "{0: {f00_hz: 112.5, position_m: [0, 0, 0]}, 1: {f00_hz: 125, position_m: [0, 0.005, 0]}}",
            "probes[1].position_m = [0.0, 0.005, 0.0] is 5.00 mm from probes[0].position_m = [0.0, 0.0, 0.0]: "
            "magnets must be more than 7.78 mm apart",
        ),
        ("{0: {f00_hz: 112.5, f00_std_hz: 20}}", "f00_std_hz = 20"),
        ("{" + ", ".join(f"{k}: {100 + 5 * k}" for k in range(MAX_PROBES + 1)) + "}", f"at most {MAX_PROBES}"),
        ("{0: [", "probes: not valid YAML: line 1, column 6"),
    ],
)
def test_a_bad_entry_is_refused_in_one_line_naming_it(text, named):
    with pytest.raises(ValueError) as refused:
        read(text)
    assert named in str(refused.value) and "\n" not in str(refused.value)


def test_a_probes_line_is_its_lever_aware_pickup_where_it_sits():
    (entry,) = read("{3: {f00_hz: 125.0, position_m: [0, 0.04, 0]}}")
    pair = FluxgatePair.paper()
    line = entry.line(0.3, pair, "difference")
    pose = Pose(theta0_rad=0.3, magnet_position_m=(0, 0.04, 0))
    expected = pickup_harmonics(pair, pose, PAPER_PROBE.lever_m, PAPER_PROBE.moment_am2)
    at_the_single_place = pickup_harmonics(pair, Pose(theta0_rad=0.3), PAPER_PROBE.lever_m, PAPER_PROBE.moment_am2)
    assert line.probe_id == 3 and line.expected_frequency_hz == 125.0 and line.theta0_rad == 0.3
    assert np.allclose(line.pickup, expected) and not np.allclose(line.pickup, at_the_single_place)
    assert entry.line(0.3, None, "difference").pickup is None  # the paper's single term


def segment(samples):
    window = RingdownWindow(0, 0.5, 1, 0, 0.0, 112.5)
    return Segment(window, 0, 20_000.0, samples, np.zeros(samples.shape, bool), 0)


def test_without_probes_the_set_is_the_estimators_own_probe_alone():
    t = np.arange(10_000) / 20_000.0
    clean = signal_t(t, 0.0, 0.3, 112.5, 0.4, 1.8, 2e-7)
    data = np.column_stack([2 * clean, clean]) + 1e-10 * np.random.default_rng(1).standard_normal((10_000, 2))
    settings = FitParameters(f00_hz=112.48, lever_aware=False).fit_settings(PAPER_PROBE)
    assert [(e.probe_id, e.probe, e.f00_hz) for e in settings.probes] == [(0, PAPER_PROBE, 112.48)]
    (alone,) = RingdownEstimator(5.0).estimate(segment(data), settings)
    assert alone.fit.ok and alone.fit.probe_id == alone.probe_id == 0, alone.fit.message
    assert abs(alone.fit.frequency_hz - 112.5) < 4 * alone.fit.frequency_std_hz
    assert alone.estimate.frequency_shift_hz == pytest.approx(alone.fit.frequency_hz - 112.48)


def test_a_nodes_probes_are_never_none_its_own_probe_a_set_of_one_as_a_listed_one_is():
    own = own_probe_entry(PAPER_PROBE, 112.48, 0.01)
    assert node_probes("", own) == node_probes("  ", own) == (own,)
    (listed,) = node_probes("{0: 112.48}", own)
    assert (listed.probe_id, listed.f00_hz, listed.probe) == (0, 112.48, with_f00(PAPER_PROBE, 112.48))
    assert [e.probe_id for e in node_probes("{3: 112.5, 1: 125.0}", own)] == [1, 3]


def test_with_probes_each_gets_its_estimate_from_its_own_f00():
    t = np.arange(10_000) / 20_000.0
    one = signal_t(t, 0.0, 0.3, 112.6, 0.4, 1.8, 2e-7) + signal_t(t, 0.0, 0.3, 125.1, 1.0, 1.8, 1e-7)
    data = np.column_stack([2 * one, one]) + 1e-10 * np.random.default_rng(2).standard_normal((10_000, 2))
    entries = read("{0: 112.5, 1: 125.0}")
    settings = FitSettings(
        entries, lambda held: [p.entry.line(p.theta0_rad, None, "difference") for p in held], FitOptions(), 0.0
    )
    estimated = RingdownEstimator(5.0).estimate(segment(data), settings)
    assert [e.fit.probe_id for e in estimated] == [0, 1]
    for e, f_true, f00 in zip(estimated, (112.6, 125.1), (112.5, 125.0)):
        assert e.fit.ok, e.fit.message
        assert abs(e.fit.frequency_hz - f_true) < 4 * e.fit.frequency_std_hz
        assert e.estimate.frequency_shift_hz == pytest.approx(e.fit.frequency_hz - f00)
    with pytest.raises(ValueError, match="2 probes are listed"):
        RingdownEstimator(5.0).begin_calibration(settings, 1e-5, 2, 10.0)
