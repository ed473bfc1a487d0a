"""The driver's cycle of several probes on the simulated device of their scene, through DeviceSession.

Requirements: nothing whose summed true peak is above the cap is ever queued, and the coil
currents the device carries never exceed it (a plan above the cap is split into groups); the
duty limit holds across the groups, counted by brute force over every window of the device's
own coil log; an emergency stop in the middle of a group switches every tone off at once and
excites nothing more; a probe whose tone overlaps another's is refused with the reason while
the others are measured, and a cycle that can excite no probe is refused with every reason;
each group's EXCITING and RINGDOWN list its probes, tones and θ0 (home + stage angle); and the
ring-down windows of a whole cycle, fitted jointly, give each probe's coupled frequency
(:meth:`SimulatedDevice.expected_frequencies_hz`, the static coupled model) within 4σ; a session
configured with its coils by name (the preset about the origin, as the driver builds it) sizes
each tone by where the device's coils are: every probe swings as planned and its window fits. A device
of one tone refuses a multi-tone drive, the simulated device of one probe the tones of probes it does
not have, and a device without a supply a supply current, each with the reason and nothing queued;
the simulated device of one probe takes its probe's tone.
"""

import dataclasses

import numpy as np
import pytest

from mows.device.backends.sim_backend import SimBackend
from mows.device.cycle.phases import CycleRequest, CycleSettings, Phase
from mows.device.cycle.tone_groups import DEFAULT_SWING_RAD, on_stage, plan_probes
from mows.device.interface import (
    CoilCommand,
    CommandResult,
    FieldCurrentCommand,
    coil_tones,
    one_tone,
)
from mows.device.simulated.scheduled import OverCap
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.probe_set import probe_lines
from mows.estimate.ringdown import COIL_OFF_SKIP_S, fit_tuning
from mows.estimate.segments import RingdownWindow, SegmentAssembler, fit_segment
from mows.physics.coils import PRESETS, CurrentCap
from mows.physics.multitone import Tone
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

SCENE = load_scenario("three_probes")
STAGE_RAD = 0.3
# The three tones sum to a 0.31 A peak: a 0.25 A cap splits them into two groups.
LOW_CAP_A = 0.25
FAST = CycleSettings(excite_s=0.5, ringdown_s=0.5, gap_s=0.1, repeats=1, tuning_steps=0, turn_settle_s=0.2)
SMALL_TONE_A = 0.03
SEED = 1
CHUNK_S = 0.1  # device time per unpaced poll
PERIOD_SAMPLES = round(SCENE.sample_rate_hz / 100.0)  # the slowest probe's period
SWING_TOLERANCE = 0.3
MAX_STEPS = 100_000  # bound for a cycle that never ends (a bug), not a timing


def session(scene=SCENE, cap_a=10.0, settings=FAST, seed=1):
    backend = SimBackend(
        SimulatedDevice(scene, np.random.default_rng(seed)), CurrentCap(cap_a), paced=False, chunk_s=CHUNK_S
    )
    config = SessionConfig(0.025, settings, scene.setup, CurrentCap(cap_a), 112.5, fit_tuning)
    return DeviceSession(backend, config, armed=True)


def run(s, request=CycleRequest(STAGE_RAD), until=None):
    """Start a cycle and step until it ends or ``until(events)`` holds: (outcomes, events, blocks)."""
    events, blocks, done = [], [], []
    events += s.step(0.0).events
    s.start_cycle(request, done.append)
    for _ in range(MAX_STEPS):
        if done or (until is not None and until(events)):
            return done, events, blocks
        output = s.step(0.0)
        events += output.events
        blocks += output.blocks
    raise AssertionError("the cycle did not end")


def on_intervals(coil_log, end_index):
    """[(on, off)] from the device's coil log of (first sample, on) changes."""
    changes = [*coil_log, (end_index, False)]
    return [(a, b) for (a, on), (b, _) in zip(changes, changes[1:]) if on]


def true_peak_a(tones, duration_s, step_s=2e-6):
    """max |Σ_k A_k·sin(θ0_k + φ_c)·sin(2π f_k t)| over coils and [0, T] on a fine grid, by hand."""
    t = np.arange(0.0, duration_s, step_s)
    phases = np.array(SCENE.setup.phases_rad)
    total = sum(
        tone.amplitude_a
        * np.sin(tone.theta0_rad + phases)[None, :]
        * np.sin(2 * np.pi * tone.frequency_hz * t)[:, None]
        for tone in tones
    )
    return float(np.abs(total).max())


def test_tones_summed_above_the_cap_are_never_queued():
    backend = SimBackend(SimulatedDevice(SCENE), CurrentCap(LOW_CAP_A), paced=False)
    plan = plan_probes(SCENE.placed_probes(), SCENE.setup, FAST.excite_s)  # one group under the scene's 10 A
    samples = round(FAST.excite_s * SCENE.sample_rate_hz)
    tones = plan.group_tones(0)
    assert max(abs(np.sin(t.theta0_rad + np.array(SCENE.setup.phases_rad))).max() * t.amplitude_a for t in tones) < (
        LOW_CAP_A
    )  # each tone alone is within the cap ...
    assert true_peak_a(tones, FAST.excite_s) > LOW_CAP_A  # ... their sum is not
    with pytest.raises(OverCap, match=r"peak at .* above the 0.25 A cap"):
        backend.device.schedule_coils(0, coil_tones(SCENE.setup, tones), samples)
    backend.send(CoilCommand(1, 0, coil_tones(SCENE.setup, tones[1:]), samples))  # within the cap: taken
    backend.poll(0.0)
    while backend.device.next_index < samples + 100:
        backend.poll(0.0)
    assert [on for _, on in backend.device.coil_log] == [True, False]
    assert 0.0 < backend.device.peak_current_a <= LOW_CAP_A


def test_a_cycle_splits_its_groups_under_the_cap_and_the_duty_limit():
    window_s, duty = 2.0, 0.3  # 0.6 s of every 2 s: the second 0.5 s excitation must wait
    s = session(cap_a=LOW_CAP_A, settings=dataclasses.replace(FAST, max_duty_cycle=duty, duty_window_s=window_s))
    (outcome,), events, _ = run(s)
    assert outcome.success, outcome.message
    assert outcome.ringdowns_recorded == 2 and outcome.refused_probes == ()
    exciting = [e for e in events if e.phase == Phase.EXCITING]
    ringdowns = [e for e in events if e.phase == Phase.RINGDOWN]
    groups = [e.probe_ids for e in exciting]
    assert [e.probe_ids for e in ringdowns] == groups and len(groups) == 2
    assert sorted(k for g in groups for k in g) == [0, 1, 2]
    tones = plan_probes(on_stage(SCENE.placed_probes(), STAGE_RAD), SCENE.setup, FAST.excite_s).tones
    assert true_peak_a(tones, FAST.excite_s) > LOW_CAP_A  # all three together would be above the cap
    assert all(true_peak_a([tones[k] for k in g], FAST.excite_s) <= LOW_CAP_A for g in groups)
    home = np.array([p.pose.theta0_rad for p in SCENE.placed_probes()])
    for e in exciting + ringdowns:
        assert e.theta0_rad == STAGE_RAD
        assert e.probe_theta0_rad == pytest.approx(tuple(home[list(e.probe_ids)] + STAGE_RAD), abs=1e-12)
        assert e.probe_frequency_hz == pytest.approx(tuple(SCENE.probes[k].probe.f00_hz for k in e.probe_ids))
    device = s.backend.device
    assert 0.0 < device.peak_current_a <= LOW_CAP_A
    assert all(0.0 < a <= LOW_CAP_A for e in exciting for a in e.currents_a)
    intervals = on_intervals(device.coil_log, device.next_index)
    assert [on for on, _ in intervals] == [e.sample_index for e in exciting]
    assert [off for _, off in intervals] == [e.sample_index for e in ringdowns]
    fs = SCENE.sample_rate_hz
    on = np.zeros(device.next_index + int(window_s * fs), int)
    for a, b in intervals:
        on[a:b] = 1
    window = int(window_s * fs)
    assert np.convolve(on, np.ones(window, int), "full").max() <= duty * window  # every window
    # The limit, not the gap, set the second start: it waited beyond ring-down + gap.
    assert intervals[1][0] > intervals[0][1] + (FAST.ringdown_s + FAST.gap_s) * fs


def test_an_emergency_stop_mid_group_switches_every_tone_off_and_excites_nothing_more():
    s = session(cap_a=LOW_CAP_A)
    done, events, _ = run(s, until=lambda ev: any(e.phase == Phase.EXCITING for e in ev))
    s.step(0.0)  # some samples into the group
    stop_index = s.backend.device.next_index
    assert s.backend.device.device.coils_on
    s.emergency_stop(True, "operator")
    for _ in range(24):  # 2.4 s of device time: the second group would have come after 1.1 s
        events += s.step(0.0).events
    (outcome,) = done
    assert not outcome.success and "emergency stop: operator" in outcome.message
    device = s.backend.device
    intervals = on_intervals(device.coil_log, device.next_index)
    assert len(intervals) == 1 and intervals[0][1] == stop_index
    assert len([e for e in events if e.phase == Phase.EXCITING]) == 1
    assert events[-1].phase == Phase.FAULT


def test_an_overlapping_tone_is_refused_with_its_reason_while_the_others_are_measured():
    probe = SCENE.probes[2].probe
    spring = probe.inertia_kgm2 * ((2 * np.pi * 101.0) ** 2 + probe.damping_per_s**2)  # f00 = 101 Hz (Eq. S1)
    near = dataclasses.replace(SCENE.probes[2], probe=probe.replace(spring_nm_per_rad=spring))
    scene = SCENE.replace(probes=(*SCENE.probes[:2], near))
    (outcome,), events, _ = run(session(scene))
    assert outcome.success, outcome.message
    ((probe_id, reason),) = outcome.refused_probes
    assert probe_id == 2 and "1 Hz from probe 0" in reason and "exciting either would ring both" in reason
    assert "refused: probe 2: 1 Hz from probe 0" in outcome.message
    assert [e.probe_ids for e in events if e.phase in (Phase.EXCITING, Phase.RINGDOWN)] == [(0, 1), (0, 1)]


def test_a_cycle_that_can_excite_no_probe_is_refused_with_every_reason():
    s = session(settings=dataclasses.replace(FAST, excitation_current_a=0.0))
    s.step(0.0)
    with pytest.raises(ValueError, match="no probe can be excited") as refused:
        s.start_cycle(CycleRequest(STAGE_RAD), lambda outcome: None)
    assert all(f"probe {k}: a tone of at most 0 A excites nothing" in str(refused.value) for k in range(3))


def test_the_windows_of_a_whole_cycle_fitted_jointly_give_each_coupled_frequency():
    # Tones of at most 30 mA swing the probes by 0.02–0.07 rad: their amplitude's shift of the
    # frequency (≤ 0.2 mHz) stays below a quarter of σ, so the swing-free coupled frequency is the truth.
    s = session(settings=dataclasses.replace(FAST, repeats=2, excitation_current_a=SMALL_TONE_A), seed=SEED)
    (outcome,), events, blocks = run(s)
    assert outcome.success, outcome.message
    device = s.backend.device.device
    expected = device.expected_frequencies_hz()  # at the cycle's orientations
    placed = on_stage(SCENE.placed_probes(), STAGE_RAD)
    assembler = SegmentAssembler(10.0)
    for e in events:
        if e.phase == Phase.RINGDOWN:
            assembler.announce(RingdownWindow(e.stamp_ns, FAST.ringdown_s, theta0_rad=e.theta0_rad))
    segments = [segment for block in blocks for segment in assembler.add_block(block)]
    assert len(segments) == 2
    windows = [e for e in events if e.phase == Phase.RINGDOWN]
    for segment, event in zip(segments, windows):
        lines = probe_lines(
            SCENE.sensors.pair, [placed[k] for k in event.probe_ids], event.probe_ids, event.probe_frequency_hz
        )
        fits = fit_segment(segment, lines, COIL_OFF_SKIP_S)
        assert [f.probe_id for f in fits] == [0, 1, 2]
        for fit in fits:
            assert fit.ok, fit.message
            pull = (fit.frequency_hz - expected[fit.probe_id]) / fit.frequency_std_hz
            assert abs(pull) < 4.0, (fit.probe_id, fit.frequency_hz, expected[fit.probe_id], fit.frequency_std_hz)


class RecordingDevice(SimulatedDevice):
    """The simulated device keeping every probe's deflection it read: the truth of the swings."""

    def __init__(self, scenario, rng):
        super().__init__(scenario, rng)
        self.theta_rad: list[np.ndarray] = []

    def read(self, n_samples):
        block = super().read(n_samples)
        self.theta_rad.append(block.theta_rad)
        return block


def test_tones_are_sized_by_the_devices_coils_not_by_the_named_preset():
    # The driver knows its coils by name and builds that preset about the origin; the scene's
    # coils sit about its first probe, 2.9 cm away. Sized by the preset's fields at the probes,
    # the tones of stage angle 0 would ring probe 1 to 0.44 rad (past its 0.42 rad stop), and a
    # joint model of constant frequencies would not describe its ring-down.
    named = PRESETS[SCENE.setup.name](current_limit_a=10.0)
    assert not np.allclose(named.coils[0].sources[0].center_m, SCENE.setup.coils[0].sources[0].center_m)
    device = RecordingDevice(SCENE, np.random.default_rng(SEED))
    backend = SimBackend(device, CurrentCap(10.0), paced=False, chunk_s=CHUNK_S)
    config = SessionConfig(0.025, FAST, named, CurrentCap(10.0), 112.5, fit_tuning)
    (outcome,), events, blocks = run(DeviceSession(backend, config, armed=True), CycleRequest(0.0))
    assert outcome.success, outcome.message
    (on,) = [e.sample_index for e in events if e.phase == Phase.EXCITING]
    (ringdown,) = [e for e in events if e.phase == Phase.RINGDOWN]
    theta = np.concatenate(device.theta_rad)
    rest = theta[on - PERIOD_SAMPLES : on].mean(axis=0)  # settled before the coils went on
    swing = np.abs(theta[ringdown.sample_index : ringdown.sample_index + 2 * PERIOD_SAMPLES] - rest).max(axis=0)
    # The plan's driven oscillator on resonance at f00 leaves out the field's shift of the
    # resonance and the neighbours' coupling: the scene's probes land within 30% of its swing.
    assert np.all(np.abs(swing / DEFAULT_SWING_RAD - 1.0) < SWING_TOLERANCE), swing
    assembler = SegmentAssembler(10.0)
    assembler.announce(RingdownWindow(ringdown.stamp_ns, FAST.ringdown_s, theta0_rad=0.0))
    (segment,) = [segment for block in blocks for segment in assembler.add_block(block)]
    placed = SCENE.placed_probes()
    lines = probe_lines(SCENE.sensors.pair, placed, ringdown.probe_ids, ringdown.probe_frequency_hz)
    for fit in fit_segment(segment, lines, COIL_OFF_SKIP_S):
        assert fit.ok, fit.report()


def test_devices_refuse_what_they_cannot_do_with_the_reason():
    tones = plan_probes(SCENE.placed_probes(), SCENE.setup, FAST.excite_s).group_tones(0)
    drive = CoilCommand(1, 0, coil_tones(SCENE.setup, tones), 100)
    with pytest.raises(ValueError, match="the serial device drives one tone at a time"):
        one_tone(drive, "serial device", len(SCENE.setup.coils))
    one_probe = SimBackend(SimulatedDevice(load_scenario()), CurrentCap(10.0), paced=False)
    with pytest.raises(ValueError, match=r"must be Tones of distinct probes 0 to 0"):
        one_probe.send(drive)  # the scene's three tones
    several = SimBackend(SimulatedDevice(SCENE), CurrentCap(10.0), paced=False)
    with pytest.raises(ValueError, match="has no field supply"):
        several.send(FieldCurrentCommand(2, 0, 1.0))
    for backend in (one_probe, several):
        items = backend.poll(0.0)  # nothing was queued: no answers, coils off
        assert not any(isinstance(item, CommandResult) for item in items)
        assert not backend.device.coil_log and not backend.device.coils_on
    # One probe is a scene of one: its own tone drives it, as the tones of a scene drive theirs.
    (placed,) = load_scenario().placed_probes()
    start = one_probe.device.next_index
    one_tone_drive = coil_tones(load_scenario().setup, (Tone.of(0, placed, placed.probe.f00_hz, 0.5),))
    one_probe.send(CoilCommand(3, 0, one_tone_drive, 100))
    (answer,) = [item for item in one_probe.poll(0.0) if isinstance(item, CommandResult)]
    assert answer.accepted and answer.applied_sample_index == start
    assert list(one_probe.device.coil_log) == [(start, True), (start + 100, False)]
    assert one_probe.device.peak_current_a > 0.1
