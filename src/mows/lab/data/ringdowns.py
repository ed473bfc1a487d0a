"""The ring-downs a driver recorded in a bag, cut out and fitted as the estimator node does them
(:mod:`mows.estimate.segments`, :mod:`mows.estimate.ringdown`): each announced RINGDOWN window
cut from the raw blocks by its device stamps and fitted with the lever-aware signal model of the
paper's geometry, or Eq. S11 (``paper_model``). :class:`BagFitting` says how, in the estimator's
parameters of the same names (``mows fit``, ``mows lab ringdown``, ``mows calibrate BAG``).

A bag of several probes sharing each window is refused (:func:`check_one_probe`): fitting one
probe per window would bias each probe's frequency by its neighbours', and the joint fit needs the
estimator's ``probes`` list (docs/multi_probe.md).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator

from mows.device.cycle.phases import Phase
from mows.device.recording.bags import read_bag
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, RingdownFit
from mows.estimate.segments import (
    RingdownWindow,
    Segment,
    SegmentAssembler,
    block_from_message,
    fit_segment,
    window_from_message,
)
from mows.lab.data.readers import RINGDOWN_TOPIC
from mows.physics.fluxgate import PAPER_DISTANCE_M, PAPER_SPACING_M, FluxgatePair
from mows.physics.probe import Probe


@dataclasses.dataclass(frozen=True)
class BagFitting:
    """Where a bag's ring-downs are (``raw_topic``, ``excitation_topic``; tuning ones too with
    ``tuning``) and how they are fitted: the lever-aware pickup of fluxgates ``sensor_distance_m``
    from the probe and ``sensor_spacing_m`` apart, or Eq. S11 (``paper_model``), leaving out
    ``coil_off_skip_s`` after the coils switch off."""

    raw_topic: str = "/mows/raw"
    excitation_topic: str = "/mows/excitation"
    tuning: bool = False
    paper_model: bool = False
    coil_off_skip_s: float = COIL_OFF_SKIP_S
    sensor_distance_m: float = PAPER_DISTANCE_M
    sensor_spacing_m: float = PAPER_SPACING_M


def fit_bag(
    path: str | os.PathLike[str], probe: Probe, how: BagFitting
) -> Iterator[tuple[RingdownWindow, RingdownFit]]:
    """(window, fit) for every ring-down in the bag, in order (tuning ones with ``how.tuning``)."""
    for segment, options in recorded_ringdowns(path, probe, how):
        yield segment.window, fit_segment(segment, options, how.coil_off_skip_s, probe.damping_per_s)


def recorded_ringdowns(
    path: str | os.PathLike[str], probe: Probe, how: BagFitting
) -> Iterator[tuple[Segment, FitOptions]]:
    """(segment, fit options) of every ring-down in the bag as ``how`` says: the estimator
    node's lever-aware pickup at the window's θ0, or Eq. S11 (``paper_model``)."""
    check_one_probe(path, how.excitation_topic)
    pair = FluxgatePair.paper(distance_m=how.sensor_distance_m, spacing_m=how.sensor_spacing_m)
    for segment in recorded_segments(path, how.raw_topic, how.excitation_topic, how.tuning):
        theta0 = segment.window.theta0_rad
        yield segment, FitOptions() if how.paper_model else FitOptions.lever_aware(pair, probe, theta0)


def check_one_probe(path: str | os.PathLike[str], excitation_topic: str) -> None:
    """ValueError when the bag's ring-downs hold several probes (module docstring): the probes
    its excitations ring (ExcitationState ``probe_ids``) and those of its recorded fits."""
    ids: set[int] = set()
    for item in read_bag(path, topics=[excitation_topic, RINGDOWN_TOPIC]):
        if item.topic == RINGDOWN_TOPIC:
            ids.add(int(item.message.probe_id))
        else:
            ids.update(int(i) for i in item.message.probe_ids)
    if len(ids) > 1:
        raise ValueError(
            f"{path} holds ring-downs of probes {', '.join(map(str, sorted(ids)))} sharing each window: fitting "
            "them needs the estimator's probes list, which mows fit and mows lab ringdown do not take "
            f"(the estimator's recorded fits are read, each probe apart, by mows lab compare {path})"
        )


def recorded_segments(
    path: str | os.PathLike[str],
    raw_topic: str = "/mows/raw",
    excitation_topic: str = "/mows/excitation",
    tuning: bool = False,
) -> Iterator[Segment]:
    """Every ring-down the driver recorded in the bag at ``path``: its announced RINGDOWN window
    (tuning ones only with ``tuning``) cut out of the raw blocks by device stamps, as
    :class:`mows.estimate.segments.Segment`, in order (as the estimator node assembles them)."""
    assembler = SegmentAssembler(buffer_s=60.0)
    for item in read_bag(path, topics=[raw_topic, excitation_topic]):
        message = item.message
        if item.topic == excitation_topic:
            if message.phase != Phase.RINGDOWN or (message.tuning and not tuning):
                continue
            yield from assembler.announce(window_from_message(message))
        else:
            yield from assembler.add_block(block_from_message(message))
