"""A workspace map's run as an I/O-free state machine, in the manner of
:class:`mows.sweep.runner.SweepRunner`: fed the goal, the end of each move (the arm there, or
its time up), each sweep's outcome, the fitted map and a cancel, it returns steps (ask the arm
for a pose, sweep there, report feedback, log a refusal, fit, the finished map). Who talks to
the arm (its reports go to the runner's :class:`mows.workspace.mapping.PoseWatch`), runs the
sweeps and keeps the clocks is the caller's business (the mapper node does it over ROS,
:mod:`mows_mapper.workspace`).

For each sweep the next pose comes from :class:`mows.workspace.mapping.PosePlan`; once the arm
reports it there and still, that report is the sweep's pose, checked
(:class:`mows.workspace.mapping.PoseWatch`) before the sweep and again after it. When the arm's
last joint turns the probe, each orientation of the sweep is a move of the arm too. A refused
pose is reported in the feedback with the reason and the plan moves on to the next; after
:data:`REFUSALS_IN_A_ROW` refusals in a row the map gives up. A sweep that fails (not its pose:
the sweep itself) ends the map. A cancel ends it before its next sweep, the pose it was at
neither refused nor reported.
"""

import dataclasses
import functools
import math
from collections.abc import Callable

from mows.physics.probe import Probe
from mows.sweep.decomposition import Decomposition
from mows.sweep.events import SweepGoal, SweepOutcome
from mows.workspace.arm import StampedPose
from mows.workspace.mapping import MapSettings, PosePlan, PoseWatch, WorkspaceMap, sweep_observations, turned
from mows.workspace.mapping import workspace_map as fitted_map

# A map gives up after this many poses in a row are refused: an arm that never gets there
REFUSALS_IN_A_ROW = 5


@dataclasses.dataclass(frozen=True)
class MapFeedback:
    """One pose visited: the ``sweep_index`` of ``n_sweeps`` it was for, why it was refused ('':
    accepted), the pose the arm reported (None: none) and the sweep's ``outcome`` (None: no sweep)."""

    sweep_index: int
    n_sweeps: int
    refusal: str
    pose: StampedPose | None
    outcome: SweepOutcome | None

    @property
    def accepted(self) -> bool:
        return not self.refusal


@dataclasses.dataclass(frozen=True)
class MapEnd:
    """A finished map: succeeded with the fitted ``map`` (its sweeps' ids and the latest
    ring-down's stamp), or failed or cancelled (no map), with the message."""

    success: bool
    message: str
    map: WorkspaceMap | None = None
    sweep_ids: tuple[int, ...] = ()
    stamp_ns: int = 0


@dataclasses.dataclass
class MapStep:
    """What the caller does next, in this order: report ``feedback``, log ``warning`` (a refused
    pose), then one of: ask the arm for ``move`` and, once :meth:`MapRunner.arrived` or the move's
    time is up, call :meth:`MapRunner.on_arrived` or :meth:`MapRunner.move_timed_out`; run the
    sweep ``sweep`` where the probe is (with ``turns``, the arm turns the probe to each
    orientation: :meth:`MapRunner.turn`) and feed its outcome to :meth:`MapRunner.on_swept`;
    call ``fit`` (CPU-bound) and feed its map to :meth:`MapRunner.on_fitted`; end with ``finished``."""

    feedback: MapFeedback | None = None
    warning: str = ""
    move: StampedPose | None = None
    sweep: SweepGoal | None = None
    turns: bool = False
    fit: Callable[[], WorkspaceMap] | None = None
    finished: MapEnd | None = None


class MapRunner:
    """One workspace map of ``settings``' workspace: ``count`` sweeps of ``goal`` by ``probe``,
    the arm's reports followed by ``watch`` (the caller feeds it ``measured_cp``)."""

    def __init__(self, settings: MapSettings, probe: Probe, watch: PoseWatch, count: int, goal: SweepGoal) -> None:
        self.watch = watch
        self._settings, self._probe, self._goal, self._count = settings, probe, goal, count
        self._plan = PosePlan(settings, probe)
        self._cancelled = False
        self._target: StampedPose | None = None  # the pose of the sweep under way
        self._moving: StampedPose | None = None  # the pose the arm was last asked for
        self._turn_rad = 0.0  # the orientation the arm was last asked to turn the probe to
        self._refused, self._refusal = 0, ""  # poses refused in a row, the last one's reason
        self._sweeps: list[tuple[Decomposition, StampedPose]] = []
        self._sweep_ids: list[int] = []
        self._stamp_ns = 0

    # --- inputs ----------------------------------------------------------------------------
    def begin(self) -> MapStep:
        """The map's first step."""
        return self._next(MapStep())

    def arrived(self) -> bool:
        """Whether the arm reports the pose it was last asked for, and has stopped there."""
        return self._moving is not None and self.watch.arrived(self._moving)

    def cancel(self) -> None:
        """No further sweep: the map ends once the move or sweep under way does (a map being
        fitted is fitted and published all the same)."""
        self._cancelled = True

    def on_arrived(self, now_ns: int) -> MapStep:
        """The arm reports the pose asked for at ``now_ns``: the sweep there, unless the pose
        cannot stand for one."""
        if self._cancelled:
            return self._end(MapEnd(False, "workspace map cancelled"))
        if problem := self.watch.start_problem(now_ns, self._settings.frame_id):
            return self._visited(problem, None)
        return MapStep(sweep=self._goal, turns=self.watch.turns_probe)

    def move_timed_out(self, timeout_s: float) -> MapStep:
        """The arm did not report the pose asked for within ``timeout_s``: the pose is refused."""
        if self._cancelled:
            return self._end(MapEnd(False, "workspace map cancelled"))
        return self._visited(f"the arm did not report the pose asked for within {timeout_s:.0f} s", None)

    def turn(self, theta0_rad: float) -> StampedPose:
        """The pose to ask the arm for, its last joint turning the probe to ``theta0_rad`` at
        the sweep's pose (then :meth:`arrived`, or :meth:`turn_timed_out`)."""
        assert self._target is not None  # the arm turns the probe only in a sweep, at its pose
        self._turn_rad, self._moving = theta0_rad, turned(self._target, theta0_rad)
        return self._moving

    def turn_timed_out(self, timeout_s: float) -> str:
        """Why the sweep cannot go on: the arm did not turn the probe within ``timeout_s``."""
        return f"the arm did not turn the probe to θ0 = {math.degrees(self._turn_rad):g}° within {timeout_s:.0f} s"

    def on_swept(self, outcome: SweepOutcome, now_ns: int) -> MapStep:
        """The sweep ended with ``outcome`` at ``now_ns``: its pose checked again, the next step."""
        if self._cancelled:
            return self._end(MapEnd(False, "workspace map cancelled"))
        if not outcome.ok:
            return self._visited(outcome.message, outcome)
        if problem := self.watch.end_problem(now_ns):
            return self._visited(problem, outcome)
        return self._accepted(outcome)

    def on_fitted(self, the_map: WorkspaceMap) -> MapStep:
        """The map is fitted: the end."""
        return self._end(MapEnd(True, the_map.report(), the_map, tuple(self._sweep_ids), self._stamp_ns))

    # --- steps -----------------------------------------------------------------------------
    def _visited(self, refusal: str, outcome: SweepOutcome | None) -> MapStep:
        """The pose asked for refused, or its sweep (``outcome``, None for none) failed."""
        feedback = MapFeedback(len(self._sweeps), self._count, refusal, self.watch.latest, outcome)
        if outcome is not None and not outcome.ok:  # not the pose: the sweep itself
            return self._end(MapEnd(False, f"workspace map failed: {outcome.message}"), MapStep(feedback=feedback))
        self._refused, self._refusal = self._refused + 1, refusal
        return self._next(MapStep(feedback=feedback, warning=f"pose refused: {refusal}"))

    def _accepted(self, outcome: SweepOutcome) -> MapStep:
        """The sweep ``outcome`` enters the map at the pose it started from."""
        pose, swept = self.watch.start, outcome.map
        assert pose is not None and swept is not None  # a sweep starts at a pose; one that succeeded has its map
        feedback = MapFeedback(len(self._sweeps), self._count, "", pose, outcome)
        self._refused = 0
        sweep = (swept.decomposition, pose)
        self._plan.swept(sweep_observations([sweep], self._probe, self._settings)[0])
        self._sweeps.append(sweep)
        self._sweep_ids.append(swept.sweep_id)
        self._stamp_ns = max(self._stamp_ns, max((p.stamp_ns for p in swept.record.points), default=0))
        return self._next(MapStep(feedback=feedback))

    def _next(self, step: MapStep) -> MapStep:
        """``step`` going on to the fit once the sweeps are in, else to the next pose."""
        if len(self._sweeps) >= self._count:
            step.fit = functools.partial(fitted_map, list(self._sweeps), self._probe, self._settings)
            return step
        if self._refused >= REFUSALS_IN_A_ROW:
            refused = f"{self._refused} poses in a row refused, the last: {self._refusal}"
            return self._end(MapEnd(False, refused), step)
        try:
            self._target = self._moving = self._plan.next_goal()
        except ValueError as error:  # no pose left within reach
            return self._end(MapEnd(False, f"workspace map failed: {error}"), step)
        step.move = self._target
        return step

    def _end(self, end: MapEnd, step: MapStep | None = None) -> MapStep:
        """``step`` (a new one for None) ending the map with ``end``."""
        step = step or MapStep()
        step.finished = end
        return step
