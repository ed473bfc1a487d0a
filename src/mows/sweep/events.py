"""What a sweep's state machine (:class:`mows.sweep.runner.SweepRunner`) is fed and what it
returns, I/O-free: the settings and the goal it is started with, the driver's answer to a cycle,
a ring-down fit as it arrives, and the steps it returns (feedback, each probe's map to publish,
the outcome); also the operator's prompt for a stage without a motor. The mapper node, the
calibrator's run and ``mows map`` (:mod:`mows.sweep.replay`) translate to and from these.
"""

import dataclasses
import math
from collections.abc import Callable

from mows.device.cycle.phases import CycleRequest
from mows.estimate.probe_set import ProbeEntry
from mows.estimate.stream import Estimated
from mows.records.stamps import NS_PER_S
from mows.sweep.decomposition import Decomposition
from mows.sweep.planner import PrecisionGoal
from mows.sweep.record import SweepPoint, SweepRecord

REPEATS_PER_ANGLE_RANGE = (1, 100)  # ring-downs per orientation a goal or the settings may ask for


@dataclasses.dataclass(frozen=True)
class SweepSettings:
    """What a goal leaves unsaid, and how the sweep is decomposed."""

    repeats_per_angle: int = 5
    angle_step_deg: float = 30.0
    model: str = "first_principles"
    f00_free: bool = False
    repeat_s: float = 0.82  # adaptive sweeps: device time of one ring-down (kick, ring-down, gap)
    turn_s: float = 0.5  # adaptive sweeps: device time of a turn and the settling
    manual_orientation: bool = False  # no motor: the operator turns the stage and confirms each orientation
    # The sweep's probes in id order, never none: one probe is a set of one (the mapper's and
    # `mows map`'s, as mows.estimate.settings.node_probes reads their ``probes`` and probe file).
    probes: tuple[ProbeEntry, ...] = dataclasses.field(kw_only=True)
    # Whether ``probes`` names them: each decomposition then in its probe's own frame, with the
    # field map of them all and no model lab (which reads one probe's sweep).
    named: bool = False

    def __post_init__(self) -> None:
        if not self.probes:
            raise ValueError("a sweep's settings need its probes (one probe is a set of one)")


@dataclasses.dataclass(frozen=True)
class SweepGoal:
    """A sweep as asked: no angles, 0 repeats or no model mean the settings' choice. With a
    ``target`` the sweep is adaptive: the angles, if any, are the orientations it may choose from."""

    theta0_rad: tuple = ()
    repeats_per_angle: int = 0
    model: str = ""
    target: PrecisionGoal | None = None

    @classmethod
    def asked(
        cls,
        theta0_rad=(),
        repeats_per_angle: int = 0,
        model: str = "",
        target: str = "",
        field_std_t: float = 0.0,
        gradient_std_t_per_m: float = 0.0,
        budget_s: float = 0.0,
    ) -> "SweepGoal":
        """The goal as a client words it (a RotationSweep goal): no ``target`` quantity is a
        sweep over the angles; zero target σ take :class:`PrecisionGoal`'s defaults and a zero
        budget means none. ValueError, with the reason, for a target that cannot be met."""
        precision = None
        if target:
            defaults = PrecisionGoal()
            precision = PrecisionGoal(
                target,
                field_std_t or defaults.field_std_t,
                gradient_std_t_per_m or defaults.gradient_std_t_per_m,
                budget_s or math.inf,
            )
        return cls(tuple(theta0_rad), repeats_per_angle, model, precision)


@dataclasses.dataclass(frozen=True)
class CycleAnswer:
    """The answer to a :class:`~mows.device.cycle.phases.CycleRequest`: the cycle that ran and how many
    ring-downs it recorded, or ``problem``, why no cycle ran ('' when it did)."""

    cycle_id: int = 0
    ringdowns_recorded: int = 0
    problem: str = ""


@dataclasses.dataclass(frozen=True)
class SweepFit:
    """One ring-down fit as it arrives: ``point`` is None unless the fit is OK. ``source`` (the
    fit as received) is handed back in the feedback untouched."""

    cycle_id: int
    tuning: bool
    point: SweepPoint | None
    source: object = None
    probe_id: int = 0

    @classmethod
    def from_message(cls, fit) -> "SweepFit":
        """A RingdownFit message, live or read from a bag."""
        point = SweepPoint.from_message(fit) if fit.status_name == "OK" else None
        return cls(fit.cycle_id, fit.tuning, point, fit, fit.probe_id)

    @classmethod
    def from_estimated(cls, estimated: Estimated) -> "SweepFit":
        """A ring-down fitted offline as the estimator fits it (:mod:`mows.estimate.stream`)."""
        fit, window, shift = estimated.fit, estimated.window, estimated.estimate
        point = None
        if fit.ok:
            t_s = estimated.stamp_ns / NS_PER_S
            point = SweepPoint.from_fit(
                fit, shift.frequency_shift_hz, shift.frequency_shift_std_hz, t_s, estimated.stamp_ns
            )
        return cls(window.cycle_id, window.tuning, point, estimated, fit.probe_id)


@dataclasses.dataclass(frozen=True)
class SweepFeedback:
    """One orientation done: its weighted mean shift and the fits of its cycle."""

    angle_index: int
    n_angles: int
    theta0_rad: float
    shift_hz: float
    shift_std_hz: float
    n_ok: int
    fits: tuple


@dataclasses.dataclass(frozen=True)
class SweepMap:
    """One probe's decomposed sweep to publish: the decomposition, its ring-downs, the f00
    used and the probe's id."""

    sweep_id: int
    decomposition: Decomposition
    record: SweepRecord
    f00_hz: float
    probe_id: int = 0
    cycle_ids: tuple[int, ...] = ()  # the sweep's measurement cycles, in order: where it begins and ends


@dataclasses.dataclass(frozen=True)
class SweepOutcome:
    """A finished sweep: succeeded (``ok``), cancelled, or failed, with why; ``map`` once it
    was decomposed (successfully or not)."""

    ok: bool
    message: str
    cancelled: bool = False
    maps: tuple[SweepMap, ...] = ()  # each probe's, in the order listed

    @property
    def map(self) -> SweepMap | None:
        """The first probe's map (the action result's), None before a decomposition."""
        return self.maps[0] if self.maps else None


@dataclasses.dataclass
class SweepStep:
    """What the caller does next, in this order: report ``feedback``, publish each of
    ``publish`` (a probe's failed decomposition too, beside others that succeeded), then one of:
    ask the operator to turn the stage to ``turn`` (rad, :func:`mows.sweep.operator.turn_prompt`) and call
    :meth:`SweepRunner.on_turned` once confirmed, run ``run_cycle``, call ``decompose``
    (CPU-bound, seconds) and feed its result, each probe's decomposition, to
    :meth:`SweepRunner.on_decomposed`, end with ``finished``, or (none of these) wait for fits."""

    feedback: SweepFeedback | None = None
    publish: tuple[SweepMap, ...] = ()
    turn: float | None = None
    run_cycle: CycleRequest | None = None
    decompose: Callable[[], list[Decomposition]] | None = None
    finished: SweepOutcome | None = None
