"""The calibration procedure as a state machine (paper Fig. 3): supply steps × orientations × cycles.

At every orientation of the plan (θ0 = 0° and 180° by default: the field term flips sign between
them, offsets do not), for every supply current of the plan: ramp the supply there and wait
until the device says it is, run one measurement cycle and collect its ring-down fits; then the
next current. The orientation is the outer loop, so a stage turned by hand is turned once per
orientation, not at every current, and the currents run up at one orientation and down at the
next, so the supply never ramps back across its range between them. On a unipolar supply (0 …
+cap, the paper's NGM202) the plan's currents are non-negative and the field's other sign comes
from θ0 + 180° alone: the applied fields along the probe are the same −cap … +cap as the paper's
plan gives, at half the cycles (:data:`UNIPOLAR_CURRENTS_A`);
:meth:`CalibrationPlan.check_supply` refuses a plan the supply cannot give before anything is
set. Every ending (done, cancelled, a refused command, a failed cycle) first ramps the supply
back to zero, and only then reports the outcome, which says whether the device confirmed zero.

The schedule does no I/O, like :class:`mows.device.cycle.sequencer.CycleSequencer`: it is fed the
device's answers (:meth:`on_supply`, :meth:`on_fit`, :meth:`on_cycle_done`, :meth:`fits_timed_out`)
and the user's :meth:`cancel`, and returns a :class:`CalibrationStep` of actions (:class:`SetSupply`, a
:class:`~mows.device.cycle.phases.CycleRequest` whose fits go to :meth:`on_fit` and whose end to
:meth:`on_cycle_done`), feedback and, at the end, the :class:`CalibrationOutcome` with the
calibration points for :func:`mows.estimate.calibration.fit_constants.calibrate_probe`.
"""

from __future__ import annotations

import dataclasses
import enum
import math

from mows.device.cycle.phases import CycleRequest
from mows.estimate.calibration.constants import CalibrationPoint, Wiring

PAPER_CURRENTS_A = (0.0, 0.5, 1.0, 1.5, 2.0, -0.5, -1.0, -1.5, -2.0)
UNIPOLAR_CURRENTS_A = tuple(i for i in PAPER_CURRENTS_A if i >= 0.0)  # θ0 + 180° gives the other sign
GRADIENT_WIRING = "gradient"  # the supply's coils anti-parallel (the lever check)


@dataclasses.dataclass(frozen=True)
class CalibrationPlan:
    """Which supply currents (A), orientations (rad) and ring-downs per cycle; ``wiring`` names
    how the supply's coils are connected (homogeneous ``helmholtz`` or a gradient wiring)."""

    currents_a: tuple = PAPER_CURRENTS_A
    theta0_rad: tuple = (0.0, math.pi)
    repeats: int = 1
    wiring: str = "helmholtz"

    def __post_init__(self):
        if not self.currents_a or not all(math.isfinite(i) for i in self.currents_a):
            raise ValueError(f"currents_a = {self.currents_a!r} must be a non-empty list of finite currents")
        if not self.theta0_rad or not all(math.isfinite(t) for t in self.theta0_rad):
            raise ValueError(f"theta0_rad = {self.theta0_rad!r} must be a non-empty list of finite angles")
        if not (isinstance(self.repeats, int) and self.repeats >= 1):
            raise ValueError(f"repeats = {self.repeats!r} must be an integer ≥ 1")

    @property
    def steps(self) -> int:
        return len(self.currents_a) * len(self.theta0_rad)

    def check_supply(self, min_current_a: float, max_current_a: float) -> None:
        """ValueError naming the first current outside the supply's range (``min_current_a`` 0:
        a unipolar supply), before any is set: never half-way through the plan. A range not
        known (NaN) checks nothing here: the device still refuses what it cannot give."""
        if not (math.isfinite(min_current_a) and math.isfinite(max_current_a)):
            return
        for current in self.currents_a:
            if not min_current_a <= current <= max_current_a:
                hint = (
                    "; a unipolar supply gets the field's other sign from θ0 + 180°, not from a negative "
                    f"current: plan currents ≥ 0, e.g. {' '.join(f'{i:g}' for i in UNIPOLAR_CURRENTS_A)}"
                    if min_current_a == 0.0 and current < 0.0
                    else ""
                )
                raise ValueError(
                    f"supply current {current:+g} A of the plan is outside the supply's range "
                    f"{min_current_a:g} … {max_current_a:+g} A{hint}"
                )


def default_currents_a(limits) -> tuple:
    """The plan's currents for a supply of ``limits`` (:class:`mows.physics.supply.SupplyLimits`):
    the paper's 0 … ±2 A on a bipolar supply, their non-negative half on a unipolar one."""
    return UNIPOLAR_CURRENTS_A if limits.min_current_a >= 0.0 else PAPER_CURRENTS_A


@dataclasses.dataclass(frozen=True)
class SetSupply:
    """Ramp the supply to ``current_a``; answer with :meth:`CalibrationSchedule.on_supply`."""

    current_a: float


@dataclasses.dataclass(frozen=True)
class Feedback:
    step: int  # 1-based index of the cycle in the plan
    steps: int
    current_a: float
    theta0_rad: float
    ringdowns: int  # usable ring-downs so far
    message: str


@dataclasses.dataclass(frozen=True)
class CalibrationOutcome:
    success: bool
    cancelled: bool
    supply_at_zero: bool  # the device confirmed the supply at zero after the end
    message: str
    points: tuple = ()
    failed: dict = dataclasses.field(default_factory=dict)  # (current, reason) → count of failed fits


@dataclasses.dataclass
class CalibrationStep:
    actions: list = dataclasses.field(default_factory=list)
    feedback: list = dataclasses.field(default_factory=list)
    outcome: CalibrationOutcome | None = None


class State(enum.StrEnum):
    """Where the schedule is; the values are what the logs show."""

    IDLE = "idle"
    RAMPING = "ramping"
    CYCLING = "cycling"
    AWAITING_FITS = "awaiting fits"
    RETURNING = "returning to zero"
    DONE = "done"


class CalibrationSchedule:
    """Runs ``plan`` once (module docstring)."""

    def __init__(self, plan: CalibrationPlan):
        self.plan = plan
        self.state = State.IDLE
        self._step = 0  # index into _order
        # (orientation, current) indices: orientations outermost, the currents up then down.
        n = len(plan.currents_a)
        self._order = [(k, i if k % 2 == 0 else n - 1 - i) for k in range(len(plan.theta0_rad)) for i in range(n)]
        self._fits_seen = 0
        self._points: list[CalibrationPoint] = []
        self._failed: dict = {}
        self._ending: tuple[bool, bool, str] | None = None  # (success, cancelled, message)

    @property
    def current_a(self) -> float:
        return self.plan.currents_a[self._order[min(self._step, self.plan.steps - 1)][1]]

    @property
    def theta0_rad(self) -> float:
        return self.plan.theta0_rad[self._order[min(self._step, self.plan.steps - 1)][0]]

    @property
    def finished(self) -> bool:
        return self.state == State.DONE

    def start(self) -> CalibrationStep:
        if self.state != State.IDLE:
            raise ValueError("a calibration schedule runs once")
        self.state = State.RAMPING
        return CalibrationStep(
            actions=[SetSupply(self.current_a)], feedback=[self._feedback(f"supply to {self.current_a:+.4f} A")]
        )

    # --- the device's answers -----------------------------------------------------------------
    def on_supply(self, accepted: bool, reason: str = "") -> CalibrationStep:
        """The device reached the commanded current (or refused it, with ``reason``)."""
        if self.state == State.RETURNING:
            return self._finish(accepted, reason)
        if self.state != State.RAMPING:
            return CalibrationStep()
        if not accepted:
            return self._end(False, False, f"the supply refused {self.current_a:+.4f} A: {reason}")
        self.state = State.CYCLING
        return CalibrationStep(
            actions=[CycleRequest(self.theta0_rad, self.plan.repeats)],
            feedback=[self._feedback(f"cycle at θ0 = {math.degrees(self.theta0_rad):.1f}°")],
        )

    def on_fit(self, fit) -> CalibrationStep:
        """A ring-down fit (``RingdownFit``) of the running cycle (tuning fits are not passed)."""
        if self.state not in (State.CYCLING, State.AWAITING_FITS):
            return CalibrationStep()
        self._fits_seen += 1
        if fit.ok:
            self._points.append(CalibrationPoint.from_fit(fit, self.plan.wiring, self.current_a))
        else:
            key = (self.current_a, fit.status.name)
            self._failed[key] = self._failed.get(key, 0) + 1
        if self.state == State.AWAITING_FITS and self._fits_seen >= self.plan.repeats:
            return self._next()
        return CalibrationStep()

    def on_cycle_done(self, success: bool, message: str = "") -> CalibrationStep:
        if self.state != State.CYCLING:
            return CalibrationStep()
        if not success:
            return self._end(
                False,
                False,
                f"the cycle at {self.current_a:+.4f} A, θ0 = {math.degrees(self.theta0_rad):.1f}° failed: {message}",
            )
        if self._fits_seen >= self.plan.repeats:
            return self._next()
        self.state = State.AWAITING_FITS
        return CalibrationStep()

    def fits_timed_out(self) -> CalibrationStep:
        """The caller waited long enough for the cycle's fits: go on without the missing ones."""
        if self.state != State.AWAITING_FITS:
            return CalibrationStep()
        key = (self.current_a, "NO_FIT")
        self._failed[key] = self._failed.get(key, 0) + self.plan.repeats - self._fits_seen
        return self._next()

    def cancel(self, reason: str = "cancelled") -> CalibrationStep:
        if self.state in (State.RETURNING, State.DONE):
            return CalibrationStep()
        return self._end(False, True, reason)

    # --- sequencing ---------------------------------------------------------------------------
    def _next(self) -> CalibrationStep:
        self._step += 1
        self._fits_seen = 0
        if self._step >= self.plan.steps:
            return self._end(
                True,
                False,
                f"{len(self._points)} ring-downs at {len(self.plan.currents_a)} supply "
                f"currents and {len(self.plan.theta0_rad)} orientations",
            )
        if self.current_a != self.plan.currents_a[self._order[self._step - 1][1]]:
            self.state = State.RAMPING
            return CalibrationStep(
                actions=[SetSupply(self.current_a)], feedback=[self._feedback(f"supply to {self.current_a:+.4f} A")]
            )
        self.state = State.CYCLING
        return CalibrationStep(
            actions=[CycleRequest(self.theta0_rad, self.plan.repeats)],
            feedback=[self._feedback(f"cycle at θ0 = {math.degrees(self.theta0_rad):.1f}°")],
        )

    def _end(self, success: bool, cancelled: bool, message: str) -> CalibrationStep:
        """Every ending ramps the supply to zero first."""
        self._ending = (success, cancelled, message)
        self.state = State.RETURNING
        return CalibrationStep(actions=[SetSupply(0.0)], feedback=[self._feedback(f"{message}; supply to zero")])

    def _finish(self, at_zero: bool, reason: str) -> CalibrationStep:
        assert self._ending is not None  # RETURNING is entered by _end only
        success, cancelled, message = self._ending
        if not at_zero:
            message += f"; THE SUPPLY DID NOT CONFIRM ZERO ({reason})"
        self.state = State.DONE
        return CalibrationStep(
            outcome=CalibrationOutcome(
                success and at_zero, cancelled, at_zero, message, tuple(self._points), dict(self._failed)
            )
        )

    def _feedback(self, message: str) -> Feedback:
        return Feedback(
            min(self._step + 1, self.plan.steps),
            self.plan.steps,
            self.current_a,
            self.theta0_rad,
            len(self._points),
            message,
        )


def scenario_wirings(scenario, gradient=None) -> dict:
    """The wirings of the scenarios' supplies at the magnet's rest position."""
    if scenario.supply is None:
        raise ValueError(f"scenario {scenario.name!r} has no supply section: the supply's field per ampere is unknown")
    where = scenario.pose.magnet_position_m
    wirings = {scenario.supply.name: Wiring.from_source(scenario.supply.name, scenario.supply.source, where)}
    if gradient is not None:
        if gradient.supply is None:
            raise ValueError(f"scenario {gradient.name!r} has no supply section")
        wirings[GRADIENT_WIRING] = Wiring.from_source(GRADIENT_WIRING, gradient.supply.source, where)
    return wirings
