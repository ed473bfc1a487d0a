"""The vocabulary of a measurement cycle (:mod:`mows.device.cycle.sequencer`): its phases and the events
that announce them (and the static-field supply's, :class:`SupplyEvent`), the settings cycles
run with, a request for one cycle, the plan it resolves to and its outcome, the step the
sequencer returns (:class:`CycleStep`), and the tuning fit it is handed.

The phase numbers are those of ``mows_msgs/ExcitationState`` PHASE_*.
"""

from __future__ import annotations

import dataclasses
import enum
import math
from collections.abc import Callable, Sequence
from typing import Protocol

from mows.records.results import Result


class Phase(enum.IntEnum):
    """The numbers of mows_msgs/ExcitationState PHASE_*."""

    IDLE = 0
    SETTLING = 1
    EXCITING = 2
    RINGDOWN = 3
    GAP = 4
    FAULT = 5


@dataclasses.dataclass(frozen=True)
class PhaseEvent:
    """A phase began at device sample ``sample_index`` (device time ``stamp_ns``)."""

    phase: Phase
    sample_index: int
    stamp_ns: int
    cycle_id: int = 0
    repeat_index: int = 0
    repeats: int = 0
    tuning: bool = False
    currents_a: tuple = ()  # signed peak current per coil, A (zeros unless EXCITING)
    frequency_hz: float = 0.0
    theta0_rad: float = 0.0
    planned_duration_s: float = 0.0  # 0: open-ended
    setup: str = ""
    reason: str = ""  # why, for FAULT
    # An excitation and its ring-down: the probes it rings (one, or the group of a multi-tone
    # drive), in one order; each probe's tone and its own orientation (its home orientation plus
    # the stage's θ0). Empty in the other phases.
    probe_ids: tuple[int, ...] = ()
    probe_frequency_hz: tuple[float, ...] = ()
    probe_theta0_rad: tuple[float, ...] = ()

    @property
    def coils_on(self) -> bool:
        return self.phase == Phase.EXCITING


@dataclasses.dataclass(frozen=True)
class SupplyEvent:
    """The static-field supply's state from device sample ``sample_index`` (device time
    ``stamp_ns``) on: ramping towards ``current_a`` (the field is changing) or steady at it.
    ``reason`` says why when the driver ramped it itself (an emergency stop), '' when commanded.
    Published as ``mows_msgs/SupplyState``."""

    sample_index: int
    stamp_ns: int
    current_a: float
    ramping: bool
    reason: str = ""


@dataclasses.dataclass(frozen=True)
class CycleSettings:
    """How cycles run (the driver's parameters of the same names). SI units."""

    excitation_current_a: float = 2.0
    excite_s: float = 0.5
    ringdown_s: float = 0.5
    gap_s: float = 1.0
    repeats: int = 3
    tuning_steps: int = 2
    turn_settle_s: float = 0.5
    max_duty_cycle: float = 0.5
    duty_window_s: float = 10.0
    confirm_timeout_s: float = 0.5  # device time a command may take to be answered

    def __post_init__(self):
        for name in ("excitation_current_a", "gap_s", "turn_settle_s"):
            check_setting(name, getattr(self, name), getattr(self, name) >= 0.0, "≥ 0")
        for name in ("excite_s", "ringdown_s", "duty_window_s", "confirm_timeout_s"):
            check_setting(name, getattr(self, name), getattr(self, name) > 0.0, "> 0")
        check_setting("max_duty_cycle", self.max_duty_cycle, 0.0 < self.max_duty_cycle <= 1.0, "in (0, 1]")
        check_setting("repeats", self.repeats, self.repeats >= 1, "≥ 1")
        check_setting("tuning_steps", self.tuning_steps, self.tuning_steps >= 0, "≥ 0")


def check_setting(name: str, value, ok: bool, allowed: str) -> None:
    """ValueError naming the setting unless ``ok`` and ``value`` is finite."""
    if not (ok and math.isfinite(value)):
        raise ValueError(f"{name} = {value!r} must be {allowed}")


class TuningResult(Result, Protocol):
    """A tuning fit's result: ``frequency_hz`` is the fitted resonance (used only if ``ok``)."""

    @property
    def frequency_hz(self) -> float: ...


# (ring-down samples (n, channels) T, sample rate Hz, each ringing probe's θ0 rad and expected
#  frequency Hz (tuples, in one order), saturated=(n, channels) flags) → a result with
# ``frequency_hz`` per probe, in that order: the estimator's fit_tuning (the joint fit of the
# probes ringing in one window), handed in by whoever builds the sequencer (the device layer
# does not fit).
TuningFit = Callable[..., Sequence[TuningResult]]


class TuningStatus(enum.Enum):
    SAMPLES_LOST = "samples of the tuning ring-down were lost"
    NEIGHBOUR_LINE = "the line fitted is another probe's"


@dataclasses.dataclass(frozen=True)
class LostTuning:
    """A tuning ring-down that was not fitted: some of its samples never arrived."""

    status: TuningStatus = TuningStatus.SAMPLES_LOST
    ok: bool = False
    frequency_hz: float = math.nan

    def report(self) -> str:
        return self.status.value


@dataclasses.dataclass(frozen=True)
class NeighbourLine:
    """A tuning fit of probe ``probe_id`` whose line lies nearer probe ``neighbour_id``'s
    resonance estimate than its own: the neighbour's line, taken where the probe's own is weaker
    or not in the window. It retunes neither probe."""

    probe_id: int
    line_hz: float
    own_estimate_hz: float
    neighbour_id: int
    neighbour_estimate_hz: float
    status: TuningStatus = TuningStatus.NEIGHBOUR_LINE
    ok: bool = False
    frequency_hz: float = math.nan

    def report(self) -> str:
        return (
            f"{self.status.value}: probe {self.probe_id}'s fit at {self.line_hz:.4f} Hz lies nearer probe "
            f"{self.neighbour_id}'s estimate {self.neighbour_estimate_hz:.4f} Hz than its own "
            f"{self.own_estimate_hz:.4f} Hz; not retuned"
        )


@dataclasses.dataclass(frozen=True)
class CycleRequest:
    """One cycle at ``theta0_rad``; None takes the value from the settings. ``frequency_hz`` is
    where to drive (a predicted resonance); None: the sequencer's present estimate.
    ``settings``: this cycle's own settings (tracking's kicks); None: the sequencer's.
    ``turned_by_hand``: the operator has turned the stage to ``theta0_rad`` and confirmed it
    (a bench whose stage has no motor refuses a cycle without it)."""

    theta0_rad: float
    repeats: int | None = None
    tuning_steps: int | None = None
    gap_s: float | None = None
    frequency_hz: float | None = None
    settings: CycleSettings | None = None
    turned_by_hand: bool = False


@dataclasses.dataclass(frozen=True)
class CyclePlan:
    """A running cycle's fixed choices: its request resolved against the settings."""

    cycle_id: int
    theta0_rad: float
    repeats: int
    tuning_steps: int
    gap_s: float
    settings: CycleSettings
    turned_by_hand: bool = False

    @classmethod
    def resolve(cls, cycle_id: int, request: CycleRequest, s: CycleSettings) -> CyclePlan:
        """The plan of ``request``. ValueError, with the reason, for a request out of range."""
        cycle = cls(
            cycle_id,
            float(request.theta0_rad),
            s.repeats if request.repeats is None else request.repeats,
            s.tuning_steps if request.tuning_steps is None else request.tuning_steps,
            s.gap_s if request.gap_s is None else request.gap_s,
            s,
            request.turned_by_hand,
        )
        CycleSettings(
            **{
                **dataclasses.asdict(s),
                "repeats": cycle.repeats,
                "tuning_steps": cycle.tuning_steps,
                "gap_s": cycle.gap_s,
            }
        )  # ValueError for a request out of range
        check_setting("theta0_rad", cycle.theta0_rad, True, "finite")
        return cycle


@dataclasses.dataclass(frozen=True)
class CycleOutcome:
    success: bool
    message: str
    cycle_id: int
    frequency_hz: float  # the excitation frequency after tuning
    ringdowns_recorded: int
    tuning_fits: tuple = ()  # each tuning ring-down's fits, one per probe it rang, in turn
    refused_probes: tuple[tuple[int, str], ...] = ()  # (probe id, reason) not excited
    cancelled: bool = False  # ended because nobody wanted it any more (a client's cancel, a deactivate): no fault


@dataclasses.dataclass
class CycleStep:
    """What the caller must do after feeding the cycle sequencer: send ``commands``, publish
    ``events``, report ``outcome`` (a cycle ended), and switch the coils off now if told."""

    commands: list = dataclasses.field(default_factory=list)
    events: list = dataclasses.field(default_factory=list)
    outcome: CycleOutcome | None = None
    coils_off_now: bool = False
