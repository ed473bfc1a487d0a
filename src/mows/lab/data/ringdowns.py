"""The ring-downs a driver recorded in a bag, fitted offline as the estimator node fits them:
the bag's raw blocks and RINGDOWN announcements go through the node's own stream core
(:class:`mows.estimate.stream.RingdownEstimator`) with the fit settings of the node's
parameters (:class:`mows.estimate.settings.FitParameters`), so each window is cut from the raw
blocks by its device stamps and fitted with the lever-aware signal model of the fluxgate pair
the parameters describe, or Eq. S11 (``lever_aware`` False). :class:`BagFitting` says where
the ring-downs are and how they are fitted (``mows fit``, ``mows lab ringdown``, ``mows calibrate BAG``).

A bag of several probes sharing each window is fitted jointly, one fit per probe, when the
parameters list the probes (``probes``, :mod:`mows.estimate.probe_set`); without that list it
is refused (:func:`check_probes`): fitting the estimator's own probe alone in each window
would bias its frequency by its neighbours'.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Iterator

from mows.device.recording.bags import read_bag
from mows.estimate.segments import Segment
from mows.estimate.settings import FitParameters
from mows.estimate.stream import Estimated, FitSettings, RingdownEstimator
from mows.lab.data.readers import RINGDOWN_TOPIC

BUFFER_S = 60.0  # raw samples kept while a window is assembled: a bag's blocks come in order, none late


@dataclasses.dataclass(frozen=True)
class BagFitting:
    """Where a bag's ring-downs are (``raw_topic``, ``excitation_topic``; tuning ones too with
    ``tuning``) and how they are fitted: the estimator's ``parameters``."""

    raw_topic: str = "/mows/raw"
    excitation_topic: str = "/mows/excitation"
    tuning: bool = False
    parameters: FitParameters = FitParameters()


def fit_bag(path: str | os.PathLike[str], settings: FitSettings, how: BagFitting) -> Iterator[Estimated]:
    """Every ring-down in the bag fitted and inverted as the estimator node does it with
    ``settings`` (e.g. ``how.parameters.fit_settings(probe)``), in order (tuning ones with
    ``how.tuning``): one :class:`Estimated` per window, or one per probe of each window when
    ``settings`` list several probes (a bag of several without them: :func:`check_probes`)."""
    estimator = RingdownEstimator(BUFFER_S)
    for segments in _completed(path, settings, how, estimator):
        yield from estimator.estimate_segments(segments, settings)


def recorded_ringdowns(path: str | os.PathLike[str], settings: FitSettings, how: BagFitting) -> Iterator[Segment]:
    """Every ring-down in the bag as ``how`` says, cut out as :func:`fit_bag` cuts them."""
    for segments in _completed(path, settings, how, RingdownEstimator(BUFFER_S)):
        yield from segments


def probes_in(path: str | os.PathLike[str], excitation_topic: str) -> list[int]:
    """The probes whose ring-downs the bag holds, in order: those its excitations ring
    (ExcitationState ``probe_ids``) and those of its recorded fits."""
    ids: set[int] = set()
    for item in read_bag(path, topics=[excitation_topic, RINGDOWN_TOPIC]):
        if item.topic == RINGDOWN_TOPIC:
            ids.add(int(item.message.probe_id))
        else:
            ids.update(int(i) for i in item.message.probe_ids)
    return sorted(ids)


def check_probes(path: str | os.PathLike[str], excitation_topic: str) -> None:
    """ValueError when the bag's ring-downs hold several probes (module docstring)."""
    if len(ids := probes_in(path, excitation_topic)) > 1:
        listed = ", ".join(f"{k}: F00_HZ" for k in ids)
        raise ValueError(
            f"{path} holds ring-downs of probes {', '.join(map(str, ids))} sharing each window: "
            f"fit them jointly with --probes '{{{listed}}}' (the estimator's probes parameter, docs/multi_probe.md)"
        )


def _completed(
    path: str | os.PathLike[str], settings: FitSettings, how: BagFitting, estimator: RingdownEstimator
) -> Iterator[list[Segment]]:
    """The ring-downs each of the bag's raw blocks and RINGDOWN announcements completes, fed to
    ``estimator`` as the node feeds it its subscriptions (tuning ones only with ``how.tuning``);
    ValueError for a bag of several probes when the parameters do not list them."""
    if not how.parameters.probes.strip():
        check_probes(path, how.excitation_topic)
    for item in read_bag(path, topics=[how.raw_topic, how.excitation_topic]):
        message = item.message
        if item.topic == how.raw_topic:
            yield estimator.add_block(message)
        else:
            yield estimator.announce(message, how.tuning)
