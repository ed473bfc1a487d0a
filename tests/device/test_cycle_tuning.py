"""The cycle's tuning, one excitation path for any number of probes: a tuning ring-down retunes
each probe's own tone from its own fit, three probes as one; a probe alone on its stage is
driven as the cycle of one probe always was (the setup's currents at the excitation current,
to the stop, at its tuned frequency, cut at the drive's turning point); a line nearer a
neighbour's estimate than the probe's own is the neighbour's, and retunes neither."""

import dataclasses
import math

import numpy as np
import pytest

from device.test_cycle import ONE, RecordingDevice
from mows.device.backends.sim_backend import SimBackend
from mows.device.cycle.phases import CycleRequest, CycleSettings, Phase
from mows.device.cycle.sequencer import CycleSequencer
from mows.device.interface import CoilCommand, CoilTone
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.probe_set import with_f00
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import CurrentCap, excitation_samples, largest_spacing
from mows.records.samples import SampleBlock
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

SCENE = load_scenario("three_probes")
STAGE_RAD = 0.3
MAX_STEPS = 100_000  # bound for a cycle that never ends (a bug), not a timing
TUNED_WITHIN_HZ = 0.005


def test_tuning_retunes_each_of_three_probes_towards_its_own_resonance():
    settings = CycleSettings(excite_s=0.5, ringdown_s=0.5, gap_s=0.1, repeats=1, tuning_steps=2, turn_settle_s=0.2)
    backend = SimBackend(SimulatedDevice(SCENE, np.random.default_rng(1)), CurrentCap(10.0), paced=False, chunk_s=0.1)
    session = DeviceSession(
        backend, SessionConfig(0.025, settings, SCENE.setup, CurrentCap(10.0), 112.5, fit_tuning), armed=True
    )
    events, done = list(session.step(0.0).events), []
    session.start_cycle(CycleRequest(STAGE_RAD), done.append)
    for _ in range(MAX_STEPS):
        if done:
            break
        events += session.step(0.0).events
    (outcome,) = done
    assert outcome.success, outcome.message
    truth_hz = backend.device.device.expected_frequencies_hz()  # each probe's, at the stage angle, coupled
    f00_hz = np.array([p.probe.f00_hz for p in SCENE.probes])
    exciting = [e for e in events if e.phase == Phase.EXCITING]
    assert [e.tuning for e in exciting] == [True, True, False]
    assert all(sorted(e.probe_ids) == [0, 1, 2] for e in exciting)  # one group of three tones
    assert len(outcome.tuning_fits) == 6 and all(fit.ok for fit in outcome.tuning_fits)
    assert exciting[0].probe_frequency_hz == pytest.approx(tuple(f00_hz[list(exciting[0].probe_ids)]))
    measured = exciting[-1]
    tuned_hz = np.array(measured.probe_frequency_hz)
    truth = truth_hz[list(measured.probe_ids)]
    start = f00_hz[list(measured.probe_ids)]
    # The field at each magnet moves its resonance off f00 (56–504 mHz here); the tuning brings
    # every tone to it, within a few σ of its fit (0.2–1 mHz) and ten times nearer than f00 was.
    assert np.all(np.abs(tuned_hz - truth) < np.minimum(TUNED_WITHIN_HZ, np.abs(start - truth) / 10)), (tuned_hz, truth)
    assert session.sequencer.frequencies_hz == pytest.approx(tuple(tuned_hz[np.argsort(measured.probe_ids)]))


def test_a_probe_alone_is_driven_at_the_setup_s_currents_to_the_stop_at_each_tuned_frequency():
    """Every coil command of a tuned cycle of one probe, built by hand from the one-probe drive:
    the setup's currents at θ0 and the excitation current, one tone at the frequency the last
    tuning fit gave, lasting to the drive's turning point."""
    rate_hz, theta0_rad, start_hz, fitted_hz = 20_000.0, 0.7, 110.0, [111.3, 112.1]
    quick = CycleSettings(excite_s=0.05, ringdown_s=0.02, gap_s=0.0, repeats=2, tuning_steps=2, turn_settle_s=0.0)
    asked = []

    @dataclasses.dataclass(frozen=True)
    class Fit:
        frequency_hz: float
        ok: bool = True

    def fit(samples, sample_rate_hz, theta0, expected_hz, saturated):
        asked.append((theta0, expected_hz))
        return [Fit(fitted_hz[len(asked) - 1])]

    setup = largest_spacing()
    sequencer = CycleSequencer(quick, setup, CurrentCap(10.0), rate_hz, start_hz, fit=fit, probes=ONE)
    sequencer.on_samples(SampleBlock(0, 0, rate_hz, np.zeros((1, 2)), np.zeros((1, 2), bool)))
    device = RecordingDevice()
    outcome = device.run(sequencer, sequencer.start(CycleRequest(theta0_rad)))
    assert outcome.success, outcome.message
    assert asked == [((theta0_rad,), (start_hz,)), ((theta0_rad,), (fitted_hz[0],))]
    drives = [c for c in device.commands if isinstance(c, CoilCommand) and not c.off]
    currents = tuple(float(i) for i in setup.currents_a(theta0_rad, quick.excitation_current_a))
    frequencies = [start_hz, fitted_hz[0], fitted_hz[1], fitted_hz[1]]
    assert [c.tones for c in drives] == [(CoilTone(0, f, currents),) for f in frequencies]
    assert [c.samples for c in drives] == [excitation_samples(quick.excite_s, f, rate_hz) for f in frequencies]
    offs = [c for c in device.commands if isinstance(c, CoilCommand) and c.off]
    assert [off.at_sample_index - on.at_sample_index for on, off in zip(drives, offs)] == [c.samples for c in drives]
    assert outcome.frequency_hz == fitted_hz[1] and math.isclose(sequencer.frequency_hz, fitted_hz[1])


@pytest.mark.parametrize(
    "lines_hz, tuned_hz",
    [
        ((100.0, 101.8), 101.0),  # probe 0's tone lies nearer probe 1's line: that line retunes neither
        ((100.4, 101.8), 100.4),  # its own line lies nearest it: retuned
    ],
)
def test_a_tuning_fit_retunes_only_the_probe_whose_estimate_its_line_is_nearest(lines_hz, tuned_hz):
    """Two probes of f00 101.0 and 102.5 Hz ring at ``lines_hz``: probe 1's tone is refused
    beside probe 0's (1.5 Hz apart: either would ring both), so each tuning window is probe 0's
    alone while probe 1 rings in it too. The fit stands in for a one-line fit that finds the
    line nearest the tone, as it does where the neighbour's line is the stronger."""
    probes = tuple(dataclasses.replace(p, probe=with_f00(p.probe, f)) for p, f in zip(SCENE.probes, (101.0, 102.5)))

    @dataclasses.dataclass(frozen=True)
    class Fit:
        frequency_hz: float
        ok: bool = True

    def fit(samples, sample_rate_hz, theta0, expected_hz, saturated):
        return [Fit(min(lines_hz, key=lambda f: abs(f - e))) for e in expected_hz]

    quick = CycleSettings(excite_s=0.5, ringdown_s=0.02, gap_s=0.0, repeats=1, tuning_steps=2, turn_settle_s=0.0)
    sequencer = CycleSequencer(quick, SCENE.setup, CurrentCap(10.0), 20_000.0, 101.0, fit=fit, probes=probes)
    sequencer.on_samples(SampleBlock(0, 0, 20_000.0, np.zeros((1, 2)), np.zeros((1, 2), bool)))
    device = RecordingDevice()
    outcome = device.run(sequencer, sequencer.start(CycleRequest(STAGE_RAD)))
    assert outcome.success, outcome.message
    assert [probe_id for probe_id, _ in outcome.refused_probes] == [1]
    drives = [c for c in device.commands if isinstance(c, CoilCommand) and not c.off]
    assert [[t.frequency_hz for t in c.tones] for c in drives][-1] == [tuned_hz]  # the measurement's tone
    assert sequencer.frequencies_hz == (tuned_hz, 102.5)
    neighbour = "probe 0's fit at 101.8000 Hz lies nearer probe 1's estimate 102.5000 Hz than its own 101.0000 Hz"
    retuned = tuned_hz != 101.0
    assert [fit.ok for fit in outcome.tuning_fits] == [retuned, retuned]
    assert retuned or all(neighbour in fit.report() for fit in outcome.tuning_fits), outcome.message
