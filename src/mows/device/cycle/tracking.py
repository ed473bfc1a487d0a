"""Tracking mode: kicks and ring-downs at one orientation, back to back, for as long as it is on.

The cycle sequencer (:mod:`mows.device.cycle.sequencer`) runs one cycle at a time; tracking chains them.
:class:`TrackingLoop` is the I/O-free state machine that says which cycle comes next: the
first turns the probe to θ0 and lets it settle, the following ones stay there (no settling:
the stage has not moved). Each cycle is ``repeats`` short kicks, each followed by its
ring-down, with no tuning excitation and no gap beyond what the duty-cycle limit imposes (the
sequencer delays a kick that would break it). The estimator fits every announced ring-down,
as it does for any cycle: a ring-down window starts when the coils answered that they are
off and ends before the next kick is switched on, and the fit leaves out the coil current's
decay and every saturated sample (:func:`mows.estimate.ringdown.usable_window`).

Every limit stays where it is: the kicks' currents are checked against the driver's cap by
the sequencer, the duty-cycle limit delays kicks, and a cycle that fails (an emergency stop,
a refused or unanswered command, a lost link) ends tracking, which stays off, with the
reason, until it is switched on again. The kick and ring-down lengths come from the physics of
the probe (:mod:`mows.device.cycle.tracking_plan`); this module only runs them.
"""

from __future__ import annotations

import dataclasses
import math

from mows.device.cycle.phases import CycleOutcome, CycleRequest, CycleSettings, check_setting

CYCLE_S = 2.0  # a tracking cycle lasts about this long: switching tracking off takes effect within it


@dataclasses.dataclass(frozen=True)
class TrackingSettings:
    """One orientation ``theta0_rad``, kicks of ``excite_s`` at ``excitation_current_a``,
    ring-downs of ``ringdown_s`` (SI units). Kicks are driven at the sequencer's present
    resonance estimate: a kick of t_k is 1/t_k wide, far wider than the resonance."""

    theta0_rad: float
    excitation_current_a: float
    excite_s: float
    ringdown_s: float

    def __post_init__(self):
        check_setting("theta0_rad", self.theta0_rad, True, "finite")
        for name in ("excitation_current_a", "excite_s", "ringdown_s"):
            check_setting(name, getattr(self, name), getattr(self, name) > 0.0, "> 0")

    @property
    def repeats(self) -> int:
        """Kicks per cycle: as many as fill ``CYCLE_S``, at least one."""
        return max(1, math.ceil(CYCLE_S / (self.excite_s + self.ringdown_s)))

    def cycle_settings(self, base: CycleSettings, settle: bool) -> CycleSettings:
        """The cycle's settings: the kicks over ``base``, whose duty-cycle limit and answer
        timeout stay; ``settle`` after turning the probe only when it has turned."""
        return dataclasses.replace(
            base,
            excitation_current_a=self.excitation_current_a,
            excite_s=self.excite_s,
            ringdown_s=self.ringdown_s,
            gap_s=0.0,
            repeats=self.repeats,
            tuning_steps=0,
            turn_settle_s=base.turn_settle_s if settle else 0.0,
        )


class TrackingLoop:
    """Which tracking cycle comes next, if any. ``start`` switches tracking on, ``stop`` off;
    :meth:`next_request` is asked whenever no cycle runs, :meth:`on_outcome` told how each ended."""

    def __init__(self) -> None:
        self.settings: TrackingSettings | None = None
        self.stopped_reason = ""  # why tracking stopped, once it ran
        self.cycles = 0
        self.ringdowns = 0
        self._settled = False  # the probe stands at θ0 since the last tracking cycle

    @property
    def on(self) -> bool:
        return self.settings is not None

    def start(self, settings: TrackingSettings) -> None:
        """Track with ``settings`` from the next idle moment on (a change of θ0 turns and settles)."""
        if self.settings is None or settings.theta0_rad != self.settings.theta0_rad:
            self._settled = False
        self.settings, self.stopped_reason = settings, ""

    def stop(self, reason: str) -> None:
        """No tracking cycle after the running one (if any); ``reason`` is reported."""
        self.settings, self.stopped_reason, self._settled = None, reason, False

    def next_request(self, base: CycleSettings) -> CycleRequest | None:
        """The next tracking cycle over the driver's ``base`` settings, or None when tracking is off."""
        if self.settings is None:
            return None
        s = self.settings
        return CycleRequest(s.theta0_rad, settings=s.cycle_settings(base, settle=not self._settled))

    def on_outcome(self, outcome: CycleOutcome) -> None:
        """A tracking cycle ended: a failed one (stop, fault, refusal) ends tracking."""
        self.cycles += 1
        self.ringdowns += outcome.ringdowns_recorded
        if outcome.success:
            self._settled = True
        else:
            self.stop(f"tracking stopped: cycle {outcome.cycle_id} failed ({outcome.message})")

    def state(self) -> dict:
        """What /diagnostics reports."""
        values = (self.on, self.cycles, self.ringdowns, self.stopped_reason)
        return dict(zip(("tracking", "tracking_cycles", "tracking_ringdowns", "tracking_stopped_reason"), values))
