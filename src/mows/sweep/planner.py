"""Adaptive rotation sweeps: which orientation next, how many ring-downs, and when to stop.

The decomposition (:mod:`mows.sweep.decompose`) is a weighted least-squares fit of the
parameters p = (Bx, By, Gs, Gd, Gxy) to the shifts Δf(θ0). Each ring-down at θ0 with standard
uncertainty σ(θ0) adds h·hᵀ/σ² to its Fisher information, h = ∂Δf(θ0)/∂p, and the covariance of
what the goal asks for (B, G or single components, with Gxx = Gs + Gd, Gyy = Gs − Gd) is the
inverse of the sum, mapped. A ring-down near 90°/270°, where the signal is at 2f and small, has
σ 4–5× larger and adds 20× less; where h is small (e.g. θ0 = 0° for By) it adds nothing to that
component. The planner picks, greedily, the orientation and the number of repeats that shrink
the goal's squared relative variances Σ_k (σ_k²/target_k²)² most per second of device time,
counting the turn of the probe only when the orientation changes, and stops when a
decomposition of the measured ring-downs reaches every target or the time budget cannot hold
another ring-down.

I/O-free: fed the record of ring-downs so far, their decomposition and the elapsed device time,
it returns the next cycle or the end. The predicted σ(θ0) of a ring-down (e.g. the Cramér–Rao
bound of :func:`mows.device.cycle.tracking_plan.ringdown_std_model`) is rescaled by what the measured
ring-downs reported.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from mows.physics.probe import Probe
from mows.sweep.decompose import unknown_count
from mows.sweep.decomposition import Decomposition
from mows.sweep.record import SweepRecord
from mows.sweep.shift_model import model_shift_hz

COMPONENTS = ("bx", "by", "gxx", "gxy", "gyy")
QUANTITIES = {"B": COMPONENTS[:2], "G": COMPONENTS[2:], "both": COMPONENTS, **{name: (name,) for name in COMPONENTS}}
# (Bx, By, Gxx, Gxy, Gyy) from the decomposition's parameters (Bx, By, Gs, Gd, Gxy[, Δf00]).
TO_COMPONENTS = np.array([[1, 0, 0, 0, 0], [0, 1, 0, 0, 0], [0, 0, 1, 1, 0], [0, 0, 0, 0, 1], [0, 0, 1, -1, 0]], float)
# A weak prior keeps the information invertible before five orientations are measured: far
# wider than any field (T) or gradient (T/m) the probe can measure, and than an f00 error (Hz).
PRIOR_STD = np.array([1e-3, 1e-3, 1.0, 1.0, 1.0, 10.0])
STEPS = np.array([1e-7, 1e-7, 1e-5, 1e-5, 1e-5])  # central differences of Δf over p
# The information is kept in µT, mT/m and Hz: in SI its entries span 1e20 and lose precision.
UNITS = np.array([1e-6, 1e-6, 1e-3, 1e-3, 1e-3, 1.0])
COMPONENT_UNITS = np.array([1e-6, 1e-6, 1e-3, 1e-3, 1e-3])
SCALE_LIMITS = (0.5, 4.0)  # the measured σ over the predicted one is believed within these
MAX_PLANNED_RINGDOWNS = 400  # the plan to the target looks this far ahead at most
NEARBY_RAD = math.radians(20.0)  # learnt σ(θ0): ring-downs this close count as the same orientation
# Until the decomposition's orientations are all measured, a visit takes at most this many
# ring-downs: the plan rests on σ and sensitivities not yet measured there.
FIRST_VISIT_REPEATS = 2
# σ_f of a ring-down before any is measured (learnt model): only that it is the same everywhere matters.
UNKNOWN_STD_HZ = 1e-3


@dataclasses.dataclass(frozen=True)
class PrecisionGoal:
    """What a sweep must reach: σ of ``quantity`` (B, G, both, or one of bx, by, gxx, gxy, gyy)
    at most ``field_std_t`` per field component and ``gradient_std_t_per_m`` per gradient
    component, within ``budget_s`` of device time."""

    quantity: str = "both"
    field_std_t: float = 20e-9
    gradient_std_t_per_m: float = 10e-6
    budget_s: float = math.inf

    def __post_init__(self):
        if self.quantity not in QUANTITIES:
            raise ValueError(f"quantity = {self.quantity!r}; use one of {', '.join(QUANTITIES)}")
        for name in ("field_std_t", "gradient_std_t_per_m"):
            value = getattr(self, name)
            if not (value > 0 and math.isfinite(value)):
                raise ValueError(f"{name} = {value!r} must be a positive number")
        if not self.budget_s > 0:
            raise ValueError(f"budget_s = {self.budget_s!r} must be > 0")

    @property
    def components(self) -> tuple:
        return QUANTITIES[self.quantity]

    def targets(self) -> np.ndarray:
        """Target σ per component of COMPONENTS; infinite for those not asked for."""
        wanted = [self.field_std_t] * 2 + [self.gradient_std_t_per_m] * 3
        return np.array([t if c in self.components else math.inf for c, t in zip(COMPONENTS, wanted)])


def achieved_std(decomposition: Decomposition) -> np.ndarray:
    """σ of (Bx, By, Gxx, Gxy, Gyy) of a decomposition; NaN where not determined."""
    if not decomposition.ok:
        return np.full(5, np.nan)
    field = np.sqrt(np.diag(decomposition.field_covariance_t2))
    gradient = np.sqrt(np.diag(decomposition.gradient_covariance))
    return np.concatenate([field, gradient])


def reached(goal: PrecisionGoal, decomposition: Decomposition | None) -> bool:
    """Whether ``decomposition`` meets every target of ``goal``."""
    if decomposition is None or not decomposition.ok:
        return False
    std = achieved_std(decomposition)
    asked = np.isfinite(goal.targets())
    return bool(np.all(std[asked] <= goal.targets()[asked]))


def beyond_reach(goal: PrecisionGoal, decomposition: Decomposition) -> bool:
    """Whether a target of ``goal`` lies below the σ the errors shared by every ring-down give
    (:attr:`Decomposition.shared_std`): no sweep of this probe reaches it."""
    asked = np.isfinite(goal.targets())
    return bool(np.any(decomposition.shared_std[asked] > goal.targets()[asked]))


@dataclasses.dataclass(frozen=True)
class PlannedCycle:
    """Run ``repeats`` ring-downs at θ0; ``predicted_std`` is σ of (Bx, By, Gxx, Gxy, Gyy) expected after."""

    theta0_rad: float
    repeats: int
    predicted_std: np.ndarray


@dataclasses.dataclass(frozen=True)
class PlanEnd:
    """The sweep ends: ``reached`` the target or not, and why."""

    reached: bool
    message: str


class AdaptivePlanner:
    """Chooses cycles for ``goal`` on ``probe`` (f00 calibrated at ``f00_hz``).

    ``repeat_s``: device time of one ring-down (excitation, ring-down, gap); ``turn_s``: of a
    turn to a new orientation (the settling included). ``ringdown_std_hz(θ0)``: predicted σ_f
    of one ring-down; None: learnt from the ring-downs measured within ``NEARBY_RAD`` (θ0 and
    θ0 + 180° alike), else from all of them. ``candidates_rad``: the orientations to choose from.
    """

    def __init__(
        self,
        probe: Probe,
        f00_hz: float,
        goal: PrecisionGoal,
        repeat_s: float,
        turn_s: float,
        ringdown_std_hz: Callable[[float], float] | None = None,
        candidates_rad=None,
        max_repeats: int = 20,
        f00_free: bool = False,
    ):
        if f00_free and {"gxx", "gyy"} & set(goal.components):
            raise ValueError("with f00 free the decomposition cannot determine Gxx and Gyy (only Gxx − Gyy and Gxy)")
        if not (repeat_s > 0 and turn_s >= 0 and max_repeats >= 1):
            raise ValueError(
                f"repeat_s = {repeat_s!r} must be > 0, turn_s = {turn_s!r} ≥ 0, max_repeats = {max_repeats!r} ≥ 1"
            )
        self.probe, self.f00_hz, self.goal = probe, float(f00_hz), goal
        self.repeat_s, self.turn_s, self.max_repeats = float(repeat_s), float(turn_s), int(max_repeats)
        self.f00_free = f00_free
        self.candidates = (
            np.radians(np.arange(0.0, 360.0, 15.0)) if candidates_rad is None else np.asarray(candidates_rad, float)
        )
        self._std_model = ringdown_std_hz
        self._predicted = None if ringdown_std_hz is None else np.array([ringdown_std_hz(a) for a in self.candidates])
        n = unknown_count(f00_free)
        self._to_components = np.hstack([TO_COMPONENTS, np.zeros((5, n - 5))])
        self._prior = np.diag((PRIOR_STD[:n] / UNITS[:n]) ** -2.0)

    # --- the choice ---------------------------------------------------------------------------
    def next(
        self, record: SweepRecord, decomposition: Decomposition | None, elapsed_s: float
    ) -> PlannedCycle | PlanEnd:
        """The next cycle, or the end of the sweep. Every cycle turns and settles the probe (the
        driver's cycle does), so its cost is the turn plus its repeats."""
        if decomposition is not None and reached(self.goal, decomposition):
            return PlanEnd(True, "target reached: " + self._describe(achieved_std(decomposition)))
        if decomposition is not None and decomposition.ok and beyond_reach(self.goal, decomposition):
            return PlanEnd(
                False,
                "target below what the errors shared by every ring-down allow (the stop's and f00's σ, "
                "which more ring-downs do not reduce): " + self._describe(decomposition.shared_std),
            )
        remaining = self.goal.budget_s - elapsed_s
        if remaining < self.turn_s + self.repeat_s:
            where = (
                self._describe(achieved_std(decomposition))
                if decomposition is not None and decomposition.ok
                else "no decomposition yet"
            )
            return PlanEnd(False, f"time budget of {self.goal.budget_s:g} s used ({elapsed_s:.1f} s): {where}")
        information = self._information(record, decomposition)
        rows = self._rows(self.candidates, decomposition)
        variance = self._candidate_variance(record)
        plan = self._plan_to_target(information, rows, variance, remaining)
        fresh = self._unvisited(record)
        if fresh.size:  # the decomposition needs this many orientations whatever the prediction says
            planned = [i for i in plan if fresh[i]]
            if not planned:
                gains = self._merit(information[None] + rows[:, :, None] * rows[:, None, :] / variance[:, None, None])
                planned = [int(np.argmin(np.where(fresh, gains, np.inf)))]
                plan = {planned[0]: 1}
            plan = {i: min(plan[i], FIRST_VISIT_REPEATS) for i in planned}
        index = max(plan, key=lambda i: plan[i])  # the orientation with the most ring-downs still to come
        repeats = min(plan[index], self.max_repeats)
        after = information + np.outer(rows[index], rows[index]) * (repeats / variance[index])
        return PlannedCycle(float(self.candidates[index]), repeats, self._component_std(after))

    def _unvisited(self, record: SweepRecord) -> np.ndarray:
        """Mask of candidates not yet measured while the record has fewer distinct orientations
        than the decomposition needs (5; 6 with f00 free); empty once it has them."""
        visited = {round(p.theta0_rad % (2.0 * math.pi), 6) for p in record.points}
        if len(visited) >= unknown_count(self.f00_free):
            return np.zeros(0, bool)
        return np.array([round(a % (2.0 * math.pi), 6) not in visited for a in self.candidates])

    def predicted_std(self, record: SweepRecord, decomposition: Decomposition | None = None) -> np.ndarray:
        """σ of (Bx, By, Gxx, Gxy, Gyy) the linearised decomposition of ``record`` would have
        (cheap: no fit; a full decomposition is worth it only once this is near the target)."""
        return self._component_std(self._information(record, decomposition))

    def _plan_to_target(self, information, rows, variance, remaining_s: float) -> dict[int, int]:
        """Ring-downs per candidate, added one at a time where they shrink the merit most per
        second (a turn is paid the first time an orientation enters the plan), until the
        prediction reaches the target or the time left is spent; at least one."""
        targets = self.goal.targets()
        asked = np.isfinite(targets)
        plan: dict[int, int] = {}
        spent = 0.0
        merit = self._merit(information)
        added = rows[:, :, None] * rows[:, None, :] / variance[:, None, None]  # one ring-down at each candidate
        for _ in range(MAX_PLANNED_RINGDOWNS):
            if plan and np.all(self._component_std(information)[asked] <= targets[asked]):
                break
            costs = self.repeat_s + np.array([0.0 if i in plan else self.turn_s for i in range(len(rows))])
            merits = self._merit(information[None] + added)
            gains = np.where(spent + costs <= remaining_s, (merit - merits) / costs, -np.inf)
            index = int(np.argmax(gains))
            if not np.isfinite(gains[index]):
                break
            information, merit = information + added[index], merits[index]
            plan[index] = plan.get(index, 0) + 1
            spent += costs[index]
        return plan

    def drive_frequency_hz(self, record: SweepRecord, decomposition: Decomposition | None, theta0_rad: float) -> float:
        """Where to drive at θ0: the decomposition's prediction, else the nearest measured
        orientation's frequency, else f00 (a short kick needs no better, :mod:`mows.sweep.fast_cycle`)."""
        if decomposition is not None and decomposition.ok:
            shift = model_shift_hz(
                self._parameters(decomposition), np.array([theta0_rad]), self.probe, self.f00_hz, "first_principles"
            )
            return float(self.f00_hz + shift[0])
        if record.points:
            nearest = min(record.points, key=lambda p: abs(math.remainder(p.theta0_rad - theta0_rad, 2.0 * math.pi)))
            return float(nearest.frequency_hz)
        return self.f00_hz

    # --- information ----------------------------------------------------------------------------
    def _parameters(self, decomposition: Decomposition | None) -> np.ndarray:
        if decomposition is not None and decomposition.ok and np.all(np.isfinite(decomposition.parameters[:5])):
            return np.asarray(decomposition.parameters[:6], float)  # the curvature is not planned for
        return np.zeros(6)

    def _rows(self, theta0_rad, decomposition) -> np.ndarray:
        """h = ∂Δf/∂p at each θ0 (small-amplitude first-principles model), p in UNITS, (n, len(p))."""
        params = self._parameters(decomposition)
        theta0 = np.asarray(theta0_rad, float)
        columns = []
        for k, step in enumerate(STEPS):
            delta = np.zeros(6)
            delta[k] = step
            columns.append(
                (
                    model_shift_hz(params + delta, theta0, self.probe, self.f00_hz, "first_principles")
                    - model_shift_hz(params - delta, theta0, self.probe, self.f00_hz, "first_principles")
                )
                / (2.0 * step)
            )
        if self.f00_free:  # Δf = f00·√(k/kM) − f00_cal: ∂/∂Δf00 ≈ 1
            columns.append(np.ones_like(theta0))
        return np.stack(columns, axis=-1) * UNITS[: len(columns)]

    def _information(self, record: SweepRecord, decomposition) -> np.ndarray:
        information = self._prior.copy()
        if record.points:
            theta0 = np.array([p.theta0_rad for p in record.points])
            std = np.array([p.shift_std_hz for p in record.points])
            angles, which = np.unique(np.round(np.mod(theta0, 2.0 * math.pi), 9), return_inverse=True)
            rows = self._rows(angles, decomposition)[which]
            information += (rows / std[:, None] ** 2).T @ rows
        return information

    def _candidate_variance(self, record: SweepRecord) -> np.ndarray:
        """Predicted σ_f² of one ring-down at each candidate, from the model rescaled by what the
        ring-downs so far reported, or (no model) from those ring-downs alone."""
        model = self._std_model
        if self._predicted is not None and model is not None:
            if not record.points:
                return self._predicted**2
            ratios = [p.shift_std_hz / model(p.theta0_rad) for p in record.points]
            return self._predicted**2 * float(np.clip(np.median(ratios), *SCALE_LIMITS)) ** 2
        if not record.points:
            return np.full(self.candidates.size, UNKNOWN_STD_HZ**2)
        theta0 = np.array([p.theta0_rad for p in record.points])
        std = np.array([p.shift_std_hz for p in record.points])
        variance = np.empty(self.candidates.size)
        for index, candidate in enumerate(self.candidates):
            # σ(θ0 + 180°) ≈ σ(θ0): the pick-up turns with the probe's axis.
            near = np.abs(np.remainder(theta0 - candidate + math.pi / 2, math.pi) - math.pi / 2) <= NEARBY_RAD
            variance[index] = np.median(std[near] if near.any() else std) ** 2
        return variance

    def _component_std(self, information) -> np.ndarray:
        """σ of (Bx, By, Gxx, Gxy, Gyy), SI, for one information matrix or a stack of them."""
        covariance = np.linalg.inv(information)
        mapped = np.einsum("ij,...jk,lk->...il", self._to_components, covariance, self._to_components)
        return np.sqrt(np.diagonal(mapped, axis1=-2, axis2=-1)) * COMPONENT_UNITS

    def _merit(self, information):
        """Σ over the goal's components of (σ²/target²)²: the worst ratios weigh most."""
        targets = self.goal.targets()
        asked = np.isfinite(targets)
        return np.sum((self._component_std(information)[..., asked] / targets[asked]) ** 4, axis=-1)

    @staticmethod
    def _describe(std: np.ndarray) -> str:
        return (
            f"σ(Bx, By) = {std[0] * 1e9:.1f}, {std[1] * 1e9:.1f} nT; "
            f"σ(Gxx, Gxy, Gyy) = {std[2] * 1e6:.1f}, {std[3] * 1e6:.1f}, {std[4] * 1e6:.1f} µT/m"
        )
