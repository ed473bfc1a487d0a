"""``mows bench throughput``: device-seconds to a target precision, protocol by protocol.

Every protocol runs on the simulated device in device time (:class:`mows.bench.rig.DeviceTimeRig`:
the driver's cycle sequencer, the estimator's segmentation and fit, no ROS) in the
``anti_helmholtz`` scene, until the first-principles decomposition of its ring-downs reaches the
target (default σ ≤ 20 nT per in-plane field component and ≤ 10 µT/m per gradient component) or
a time limit. The fixed protocols are checked after every orientation once enough are measured
to decompose (:func:`mows.sweep.decompose.orientations_problem`):

* ``paper``: the paper's protocol, 12 orientations, two tuning excitations and five ring-downs
  of 60 periods each, 10 s gaps (2 A, 0.5 s excitations);
* ``default``: today's node defaults (driver: 2 A, 0.5 s excitation and ring-down, two tuning
  excitations, 1 s gaps; mapper: 30° steps, five ring-downs per orientation);
* ``demo``: the demo's sweep (8 orientations × 2 ring-downs, one tuning excitation, 0.2 s gaps);
* ``adaptive``: the cycle from physics (:mod:`mows.sweep.fast_cycle`) and the planner
  (:mod:`mows.sweep.planner`), fed the noise measured in the first 25 ms of samples.

All keep the same 0.5 s for turning and settling the probe (the simulated stage turns at once;
a real one needs time, and that is the driver's default). f00 is the probe's calibrated value.
Figures: device seconds to target, σ reached, σ·√T (nT·√s, µT/m·√s), pulls against the scene's
truth, and the peak coil current and worst duty-cycle window seen.

``points_per_minute``: map points (one probe's B and G to a target σ) per minute of device
time with one probe and with the three probes of the ``three_probes`` scene excited together
(:mod:`mows.bench.multiprobe_throughput`), at the same target for both (default σ ≤ 200 nT per
field and ≤ 100 µT/m per gradient component; rounds of the multi-probe cycle, the target
checked after every point).

``tracking``: the driver's tracking mode (its plan and its loop of cycles,
:mod:`mows.device.cycle.tracking`) at θ0 = 0°, ring-downs as short as the Cramér–Rao bound allows for
σ ≤ 0.2 µT and σ ≤ 1 µT; measured: updates per device second and the scatter of the estimates.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from mows.bench import multiprobe_throughput
from mows.bench.rig import DeviceTimeRig, max_duty_fraction
from mows.device.cycle.phases import CycleRequest, CycleSettings
from mows.device.cycle.tracking import TrackingLoop, TrackingSettings
from mows.device.cycle.tracking_plan import tracking_plan
from mows.estimate.axis import estimate_along_axis
from mows.lab.data.truth import scene_truth
from mows.records.stamps import NS_PER_S
from mows.sim.scenario import load_scenario
from mows.sweep.decompose import orientations_problem
from mows.sweep.decomposition import Decomposition
from mows.sweep.fast_cycle import PAPER_CYCLE, PAPER_ORIENTATIONS, fit_std_model, plan_cycle
from mows.sweep.planner import COMPONENTS, AdaptivePlanner, PlanEnd, PrecisionGoal, achieved_std, reached
from mows.sweep.record import SweepPoint, SweepRecord

SCENARIO = "anti_helmholtz"
CAP_A = 10.0
# The simulated lever is released 0.03°–0.04° beyond its housing's stop (docs/physics.md §6.4):
# the probe file of the simulated probe states its stop to this, and the map carries it.
SIMULATED_STOP_STD_RAD = math.radians(0.05)
TURN_SETTLE_S = 0.5
DECOMPOSE_NEAR = 1.25
PROTOCOLS = {
    "paper": (dataclasses.replace(PAPER_CYCLE, turn_settle_s=TURN_SETTLE_S), PAPER_ORIENTATIONS),
    "default": (CycleSettings(repeats=5, tuning_steps=2, gap_s=1.0, turn_settle_s=TURN_SETTLE_S), 12),
    "demo": (CycleSettings(repeats=2, tuning_steps=1, gap_s=0.2, turn_settle_s=TURN_SETTLE_S), 8),
}


@dataclasses.dataclass
class ProtocolResult:
    name: str
    device_s: float
    reached: bool
    message: str
    std: np.ndarray  # σ of (Bx, By, Gxx, Gxy, Gyy), T and T/m
    pulls: np.ndarray  # (estimate − truth)/σ
    ringdowns: int
    orientations: int
    peak_current_a: float
    max_duty: float

    def figures(self) -> dict:
        field_scale, gradient_scale = 1e9, 1e6
        scale = np.array([field_scale] * 2 + [gradient_scale] * 3)
        root_t = math.sqrt(self.device_s)
        return {
            f"{self.name}_s": self.device_s,
            f"{self.name}_reached": self.reached,
            f"{self.name}_std_nT_uT_per_m": (self.std * scale).tolist(),
            f"{self.name}_std_sqrt_s": (self.std * scale * root_t).tolist(),
            f"{self.name}_max_abs_pull": float(np.max(np.abs(self.pulls))) if self.pulls.size else math.nan,
            f"{self.name}_ringdowns": self.ringdowns,
            f"{self.name}_orientations": self.orientations,
            f"{self.name}_peak_current_a": self.peak_current_a,
            f"{self.name}_max_duty": self.max_duty,
        }


class _Sweep:
    """Ring-downs of one protocol, decomposed as the mapper does once the linearised prediction
    (:meth:`AdaptivePlanner.predicted_std`, no fit) is within ``DECOMPOSE_NEAR`` of the target:
    a first-principles decomposition costs seconds."""

    def __init__(self, scenario, goal: PrecisionGoal):
        self.scenario, self.goal = scenario, goal
        self.probe = scenario.probe.replace(theta_stop_std_rad=SIMULATED_STOP_STD_RAD)
        self.record = SweepRecord()
        self.decomposition: Decomposition | None = None
        # Only its prediction from measured ring-downs is used: no σ model for unmeasured ones.
        self._predictor = AdaptivePlanner(self.probe, self.probe.f00_hz, goal, 1.0, 0.0, lambda theta0: math.nan)

    def add(self, measured) -> None:
        for ringdown in measured:
            fit = ringdown.fit
            if fit.ok:
                self.record.add(
                    SweepPoint.from_fit(
                        fit,
                        fit.frequency_hz - self.probe.f00_hz,
                        fit.frequency_std_hz,
                        ringdown.window.start_ns / NS_PER_S,
                    )
                )
            else:
                self.record.failed += 1
        if orientations_problem([p.theta0_rad for p in self.record.points]):
            return
        targets = self.goal.targets()
        asked = np.isfinite(targets)
        predicted = self._predictor.predicted_std(self.record, self.decomposition)
        if self.decomposition is None or np.all(predicted[asked] <= DECOMPOSE_NEAR * targets[asked]):
            self.decomposition = self.record.decompose(self.probe, self.probe.f00_hz)

    def result(self, name, rig, goal, message) -> ProtocolResult:
        d = self.decomposition
        std = achieved_std(d) if d is not None else np.full(5, np.nan)
        estimate = np.concatenate([d.field_t, d.gradient_t_per_m]) if d is not None and d.ok else np.full(5, np.nan)
        window = round(rig.sequencer.settings.duty_window_s * rig.fs)
        return ProtocolResult(
            name,
            rig.time_s,
            reached(goal, d),
            message,
            std,
            (estimate - scene_truth(self.scenario)) / std,
            len(self.record.points),
            len({round(p.theta0_rad, 9) for p in self.record.points}),
            rig.peak_current_a,
            max_duty_fraction(rig.coil_intervals(), window),
        )


def fixed_protocol(
    name: str, goal: PrecisionGoal = PrecisionGoal(), max_s: float = 4000.0, seed: int = 1
) -> ProtocolResult:
    """A protocol of fixed orientations and repeats, sweep after sweep until the target."""
    scenario = load_scenario(SCENARIO)
    settings, n_angles = PROTOCOLS[name]
    rig = DeviceTimeRig(scenario, settings, CAP_A, seed)
    sweep = _Sweep(scenario, goal)
    angles = np.radians(np.arange(n_angles) * 360.0 / n_angles)
    while rig.time_s < max_s:
        for theta0 in angles:
            cycle = rig.run_cycle(CycleRequest(float(theta0)))
            if not cycle.outcome.success:
                return sweep.result(name, rig, goal, f"cycle failed: {cycle.outcome.message}")
            sweep.add(cycle.measured)
            if reached(goal, sweep.decomposition):
                return sweep.result(name, rig, goal, "target reached")
    return sweep.result(name, rig, goal, f"not reached in {max_s:g} s")


def adaptive_protocol(goal: PrecisionGoal = PrecisionGoal(), seed: int = 1, scenario=None):
    """The physics cycle and the adaptive planner: (result, the cycle plan)."""
    scenario = scenario or load_scenario(SCENARIO)
    probe = scenario.probe
    rig = DeviceTimeRig(scenario, CycleSettings(), CAP_A, seed)
    std = fit_std_model(scenario, rig.first_block_noise_std_t())
    plan = plan_cycle(probe, scenario.setup, scenario.pose, std, CAP_A, CycleSettings().max_duty_cycle)
    rig.set_settings(
        CycleSettings(
            excitation_current_a=plan.excitation_current_a,
            excite_s=plan.excite_s,
            ringdown_s=plan.ringdown_s,
            gap_s=plan.gap_s,
            repeats=1,
            tuning_steps=plan.tuning_steps,
            turn_settle_s=TURN_SETTLE_S,
        )
    )
    planner = AdaptivePlanner(
        probe, probe.f00_hz, goal, plan.cycle_s, TURN_SETTLE_S, lambda theta0: std(theta0, plan.ringdown_s)
    )
    sweep = _Sweep(scenario, goal)
    while True:
        step = planner.next(sweep.record, sweep.decomposition, rig.time_s)
        if isinstance(step, PlanEnd):
            return sweep.result("adaptive", rig, goal, step.message), plan
        frequency = planner.drive_frequency_hz(sweep.record, sweep.decomposition, step.theta0_rad)
        cycle = rig.run_cycle(CycleRequest(step.theta0_rad, repeats=step.repeats, frequency_hz=frequency))
        if not cycle.outcome.success:
            return sweep.result("adaptive", rig, goal, f"cycle failed: {cycle.outcome.message}"), plan
        sweep.add(cycle.measured)


def tracking(target_std_t: float, updates: int = 40, theta0_rad: float = 0.0, seed: int = 2) -> dict:
    """The driver's tracking mode at θ0 for σ ≤ ``target_std_t`` of B along the axis: its plan
    and loop (:mod:`mows.device.cycle.tracking`) fed the noise measured in the first samples, and what
    it measured (updates per device second between consecutive fitted ring-downs, their scatter)."""
    scenario = load_scenario(SCENARIO)
    probe = scenario.probe
    rig = DeviceTimeRig(scenario, CycleSettings(turn_settle_s=TURN_SETTLE_S), CAP_A, seed)
    plan = tracking_plan(
        scenario, theta0_rad, target_std_t, CAP_A, fit_std_model(scenario, rig.first_block_noise_std_t())
    )
    figures: dict[str, object] = {
        "target_t": target_std_t,
        "feasible": plan.feasible,
        "bound_t": plan.bound_std_t,
        "ringdown_s": plan.ringdown_s,
        "kick_s": plan.excite_s,
        "planned_updates_per_s": plan.updates_per_s,
    }
    if not plan.feasible:
        return figures
    loop = TrackingLoop()
    loop.start(TrackingSettings(theta0_rad, CAP_A, plan.excite_s, plan.ringdown_s))
    measured = rig.run_tracking(loop, updates)
    good = [m for m in measured if m.fit.ok]
    estimates = [estimate_along_axis(m.fit, probe, probe.f00_hz) for m in good]
    axis = np.array([e.field_along_axis_t for e in estimates])
    ends = np.array([m.window.start_ns / NS_PER_S + m.window.duration_s for m in good])
    window = round(rig.sequencer.settings.duty_window_s * rig.fs)
    figures.update(
        {
            "tracking_on": loop.on,
            "message": loop.stopped_reason,
            "updates": len(good),
            "failed_fits": len(measured) - len(good),
            "updates_per_s": (len(good) - 1) / float(ends[-1] - ends[0]) if len(good) > 1 else math.nan,
            "scatter_t": float(np.std(axis, ddof=1)) if axis.size > 1 else math.nan,
            "reported_std_t": float(np.mean([e.field_along_axis_std_t for e in estimates])) if good else math.nan,
            # θmax is reported only where a fit pins it; the start swing is the stop's (readers)
            "amplitudes_determined": sum(math.isfinite(m.fit.amplitude_rad) for m in good),
            "peak_current_a": rig.peak_current_a,
            "max_duty": max_duty_fraction(rig.coil_intervals(), window),
        }
    )
    return figures


def run(
    protocols=("paper", "default", "demo"),
    tracking_updates: int = 40,
    field_std_t: float = PrecisionGoal.field_std_t,
    gradient_std_t_per_m: float = PrecisionGoal.gradient_std_t_per_m,
    multiprobe_field_std_t: float = 200e-9,
    multiprobe_gradient_std_t_per_m: float = 100e-6,
    multiprobe_points: int = 8,
    multiprobe_sweeps: int = 6,
) -> dict:
    """Figures for ``mows bench throughput``: the sweeps to σ ≤ ``field_std_t`` per field and
    ``gradient_std_t_per_m`` per gradient component, ``tracking_updates`` tracking updates, and
    the map points per minute of one and of three probes to σ ≤ ``multiprobe_field_std_t`` and
    ``multiprobe_gradient_std_t_per_m`` (sweeps of
    ``multiprobe_points`` orientations, at most ``multiprobe_sweeps``)."""
    goal = PrecisionGoal(field_std_t=field_std_t, gradient_std_t_per_m=gradient_std_t_per_m)
    figures = {
        "scenario": SCENARIO,
        "target_field_t": goal.field_std_t,
        "target_gradient_t_per_m": goal.gradient_std_t_per_m,
        "components": list(COMPONENTS),
    }
    adaptive, plan = adaptive_protocol(goal)
    figures.update(adaptive.figures())
    figures.update(
        {
            "adaptive_message": adaptive.message,
            "plan_excite_s": plan.excite_s,
            "plan_ringdown_s": plan.ringdown_s,
            "plan_gap_s": plan.gap_s,
            "plan_current_a": plan.excitation_current_a,
            "plan_tuning_steps": plan.tuning_steps,
            "plan_ringdown_crb_hz": plan.ringdown_std_hz,
        }
    )
    for name in protocols:
        result = fixed_protocol(name, goal)
        figures.update(result.figures())
        if result.reached and adaptive.reached:
            figures[f"{name}_over_adaptive"] = result.device_s / adaptive.device_s
    precise, fast = tracking(0.2e-6, tracking_updates), tracking(1e-6, tracking_updates)
    figures["tracking_hz"] = precise.get("updates_per_s", math.nan)
    figures["tracking_std_t"] = precise.get("scatter_t", math.nan)
    figures["tracking_1ut_hz"] = fast.get("updates_per_s", math.nan)
    figures["tracking_1ut_std_t"] = fast.get("scatter_t", math.nan)
    figures["tracking_0.2ut"] = precise
    figures["tracking_1ut"] = fast
    several_goal = PrecisionGoal(
        field_std_t=multiprobe_field_std_t, gradient_std_t_per_m=multiprobe_gradient_std_t_per_m
    )
    several = multiprobe_throughput.run(several_goal, multiprobe_points, multiprobe_sweeps)
    rates = {"1_probe": several["one"]["points_per_minute"], "3_probes": several["all"]["points_per_minute"]}
    figures["points_per_minute"] = rates
    figures.update({f"points_per_minute_{k}": v for k, v in rates.items()})
    figures["points_per_minute_ratio"] = several["ratio"]
    figures["points_per_minute_target_field_t"] = several_goal.field_std_t
    figures["points_per_minute_target_gradient_t_per_m"] = several_goal.gradient_std_t_per_m
    figures["points_per_minute_runs"] = several
    return figures
