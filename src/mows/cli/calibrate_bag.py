"""The calibration points of a bag the driver recorded while a calibration ran (``mows calibrate BAG``).

Every ring-down is fitted as the estimator node fits it (:func:`mows.lab.data.ringdowns.fit_bag`, the path
of ``mows fit``); its supply current is the one the driver's ``mows_msgs/SupplyState`` messages
(``/mows/supply``) say was steady from before the ring-down began until after it ended: the
current the calibration action paired the estimator's fit with. Ring-downs during a ramp, after
the emergency stop's ramp to zero or before the first supply state are left out and counted.
A bag recorded before the driver published its supply states cannot say at which current a
ring-down was taken: it is refused with :class:`mows.device.recording.bags.BagError` (``mows calibrate``:
one line, exit status 2).
"""

from __future__ import annotations

import bisect
import dataclasses

from mows.device.backends.bag_backend import SUPPLY_TYPE
from mows.device.recording.bags import BagError, read_bag
from mows.estimate.calibration.constants import CalibrationPoint
from mows.estimate.stream import FitSettings
from mows.lab.data.ringdowns import BagFitting, fit_bag, probes_in
from mows.records import stamps
from mows.records.stamps import NS_PER_S

SUPPLY_TOPIC = "/mows/supply"


@dataclasses.dataclass(frozen=True)
class SupplyTimeline:
    """The recorded supply states in device time, in order."""

    stamps_ns: tuple
    currents_a: tuple
    ramping: tuple

    @classmethod
    def of_bag(cls, path, topic: str = SUPPLY_TOPIC) -> SupplyTimeline:
        """The states on ``topic``; BagError for a bag that has none."""
        # In device time; states of one stamp in the order the driver published them (a ramp that
        # is no ramp, to the present current, starts and ends at one sample: steady comes last).
        states = sorted(
            (
                (stamps.nanoseconds(m.message.header.stamp), float(m.message.current_a), bool(m.message.ramping))
                for m in read_bag(path, topics=[topic])
                if m.msgtype == SUPPLY_TYPE
            ),
            key=lambda state: state[0],
        )
        if not states:
            raise BagError(
                f"{path} has no supply current (no {SUPPLY_TYPE} on {topic}): it was recorded by a driver "
                "that did not publish its supply, so no ring-down's applied field is known; "
                "calibrate from a table instead (mows calibrate TABLE)"
            )
        return cls(*map(tuple, zip(*states)))

    def steady_current_a(self, start_ns: int, end_ns: int) -> float | None:
        """The supply current that held steady over [start_ns, end_ns], or None (ramping, changed
        within, or not yet known)."""
        i = bisect.bisect_right(self.stamps_ns, start_ns) - 1
        if i < 0 or self.ramping[i]:
            return None
        if i + 1 < len(self.stamps_ns) and self.stamps_ns[i + 1] <= end_ns:
            return None
        return self.currents_a[i]


def bag_points(path, settings: FitSettings, wiring: str, supply_topic: str, how: BagFitting) -> tuple[list, dict, int]:
    """The bag's ring-downs as calibration points of ``wiring``, found as ``how`` says and fitted
    with ``settings`` (the nominal probe's pickup), each at the current the supply states on
    ``supply_topic`` held steady over it: (points, failed fits by (current, status), ring-downs
    at no steady current)."""
    if len(ids := probes_in(path, how.excitation_topic)) > 1:
        raise ValueError(
            f"{path} holds ring-downs of probes {', '.join(map(str, ids))} sharing each window: a calibration is of "
            "one probe; record each probe's calibration alone"
        )
    timeline = SupplyTimeline.of_bag(path, supply_topic)
    points: list[CalibrationPoint] = []
    failed: dict[tuple[float, str], int] = {}
    unknown = 0
    for estimated in fit_bag(path, settings, how):
        window, fit = estimated.window, estimated.fit
        end_ns = window.start_ns + round(window.duration_s * NS_PER_S)
        current = timeline.steady_current_a(window.start_ns, end_ns)
        if current is None:
            unknown += 1
        elif fit.ok:
            points.append(CalibrationPoint.from_fit(fit, wiring, current))
        else:
            failed[(current, fit.status.name)] = failed.get((current, fit.status.name), 0) + 1
    return points, failed, unknown
