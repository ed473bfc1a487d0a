"""The ring-down window of an excitation of several probes, fitted jointly: one fit per probe.

A multi-tone excitation (:mod:`mows.physics.multitone`) leaves every probe of its group ringing
down in the same window, cut out of the stream like one probe's
(:class:`mows.estimate.segments.SegmentAssembler`). :func:`probe_lines` says what the joint
fit (:func:`mows.estimate.ringdown.joint.fit_ringdowns`) is told about each probe: its id, its
θ0, the frequency it was excited at and the exact pickup of its magnet swinging on its lever
(:func:`mows.physics.fluxgate.pickup_harmonics`) seen by the fluxgate pair, which differs from
probe to probe with where each sits. :func:`fit_joint_segment` fits a window, or refuses one
with samples missing (``FitStatus.DATA_GAP`` for every probe), never patched.
"""

from __future__ import annotations

from collections.abc import Sequence

from mows.estimate.ringdown.joint import JointOptions, ProbeLine, fit_ringdowns
from mows.estimate.ringdown.types import FitStatus, RingdownFit, failure
from mows.estimate.segments import Segment, gap_message
from mows.physics.coupling import PlacedProbe
from mows.physics.fluxgate import FluxgatePair, pickup_harmonics, pickup_scale_t


def probe_lines(
    pair: FluxgatePair,
    placed: Sequence[PlacedProbe],
    probe_ids: Sequence[int],
    expected_frequency_hz: Sequence[float],
    channels: str = JointOptions.channels,
) -> list[ProbeLine]:
    """One :class:`ProbeLine` per probe: ``placed[k]`` (at its present θ0) with id
    ``probe_ids[k]``, its line expected at ``expected_frequency_hz[k]`` (its tone's)."""
    return [
        ProbeLine(
            probe_id=int(probe_id),
            theta0_rad=p.pose.theta0_rad,
            expected_frequency_hz=float(f),
            pickup=tuple(pickup_harmonics(pair, p.pose, p.probe.lever_m, p.probe.moment_am2, combine=channels)),
            damping_guess_per_s=p.probe.damping_per_s,
            pickup_scale_t=pickup_scale_t(pair, p.pose.magnet_position_m, p.probe.moment_am2, channels),
        )
        for p, probe_id, f in zip(placed, probe_ids, expected_frequency_hz)
    ]


def fit_joint_segment(
    segment: Segment,
    lines: Sequence[ProbeLine],
    coil_off_skip_s: float = 0.0,
    options: JointOptions = JointOptions(),
) -> list[RingdownFit]:
    """The joint fit of one assembled window, one :class:`RingdownFit` per line (in order)."""
    if segment.missing_samples:
        message = gap_message(segment)
        return [
            failure(FitStatus.DATA_GAP, message, theta0_rad=line.theta0_rad, probe_id=line.probe_id) for line in lines
        ]
    return fit_ringdowns(segment.samples_t, segment.sample_rate_hz, lines, segment.saturated, options, coil_off_skip_s)
