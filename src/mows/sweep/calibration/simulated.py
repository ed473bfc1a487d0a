"""The probe calibration on the simulated device in simulated device time: the calibration
schedule (:class:`mows.sweep.calibration.schedule.CalibrationSchedule`) run as the driver runs
its steps (:class:`mows.device.stream.device_time.DeviceTimeLoop`: the supply's ramps and the
measurement cycles), its ring-downs fitted as the estimator fits them, and the constants found
set against the simulated probe's own (``mows calibrate --simulate``, ``mows-demo``).

May import: ``mows.device`` (the device-time loop), ``mows.estimate``, ``mows.physics``,
``mows.records`` and the rest of ``mows.sweep``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from mows.device.cycle.phases import CycleSettings, Phase, PhaseEvent
from mows.device.stream.device_time import DeviceTimeLoop, scheduled_device
from mows.estimate.probe_set import ProbeEntry, window_probes
from mows.estimate.ringdown import COIL_OFF_SKIP_S, FitOptions, fit_tuning
from mows.estimate.segments import RingdownWindow, SegmentAssembler, fit_segment
from mows.physics.coils import CurrentCap
from mows.physics.probe import Probe
from mows.sweep.calibration.schedule import (
    GRADIENT_WIRING,
    CalibrationOutcome,
    CalibrationPlan,
    CalibrationSchedule,
    SetSupply,
)

SUPPLY_SETTLE_S = 0.5  # the probe rings after a supply step: wait before the next cycle
SEGMENT_BUFFER_S = 5.0  # the stream kept to cut the ring-downs from, as the estimator keeps it


def simulated_points(scenario, gradient, nominal: Probe, plan: CalibrationPlan, seed: int) -> tuple[list, dict]:
    """The points of ``plan`` (its wiring the homogeneous one) simulated on ``scenario`` with the
    noise ``seed`` and, with a ``gradient`` scenario, those of the same plan on its gradient
    wiring (seed + 1), with the failed cycles' reasons. ValueError when a schedule stopped."""
    outcome = _succeeded(simulate_calibration(scenario.replace(seed=seed), plan, nominal))
    points, failed = list(outcome.points), dict(outcome.failed)
    if gradient is not None:
        gradient_plan = dataclasses.replace(plan, wiring=GRADIENT_WIRING)
        more = _succeeded(simulate_calibration(gradient.replace(seed=seed + 1), gradient_plan, nominal))
        points += more.points
        failed.update(more.failed)
    return points, failed


def _succeeded(outcome: CalibrationOutcome) -> CalibrationOutcome:
    """The outcome of a schedule that ran to its end; ValueError with its reason otherwise."""
    if not outcome.success:
        raise ValueError(f"the simulated calibration stopped: {outcome.message}")
    return outcome


def simulate_calibration(scenario, plan: CalibrationPlan, nominal: Probe, on_feedback=None) -> CalibrationOutcome:
    """Run :class:`CalibrationSchedule` on the simulated device of ``scenario`` in device time.

    The supply ramps and the cycles run as the driver runs them
    (:class:`mows.device.stream.device_time.DeviceTimeLoop`: the supply's cap, slew and resolution;
    the driver's cycle with its default settings but the scene's excitation), each cycle driven
    where the paper's tuning leaves the drive (:func:`_resonance_hz`), and every measurement
    ring-down is cut from the stream and fitted as the estimator does, with the lever-aware
    pickup of the **nominal** probe (the true lever is what is being calibrated). ValueError if
    the schedule does not end at zero current.
    """
    excitation = scenario.excitation
    settings = CycleSettings(
        excitation_current_a=excitation.amplitude_a, excite_s=excitation.excite_s, ringdown_s=excitation.ringdown_s
    )
    fits = _NominalFits(scenario.sensors.pair, nominal)
    device = scheduled_device(scenario, CurrentCap(), np.random.default_rng(scenario.seed))
    loop = DeviceTimeLoop(device, settings, fit=fit_tuning, on_block=fits.block, on_event=fits.event)
    schedule = CalibrationSchedule(plan)
    pending = [schedule.start()]
    while pending:
        step = pending.pop(0)
        for feedback in step.feedback:
            if on_feedback:
                on_feedback(feedback)
        if step.outcome is not None:
            if device.device.field_current_a != 0.0:
                raise ValueError(f"the supply is at {device.device.field_current_a} A after the calibration")
            return step.outcome
        for action in step.actions:
            if isinstance(action, SetSupply):
                refused = loop.ramp_supply(action.current_a, SUPPLY_SETTLE_S)
                pending.append(schedule.on_supply(not refused, refused))
                continue
            tuned = _resonance_hz(device.device, action.theta0_rad)
            outcome = loop.run_cycle(dataclasses.replace(action, frequency_hz=tuned, tuning_steps=0))
            pending += [schedule.on_fit(fit) for fit in fits.take()]
            pending.append(schedule.on_cycle_done(outcome.success, outcome.message))
    raise RuntimeError("the calibration schedule stopped without an outcome")


def _resonance_hz(device, theta0_rad: float) -> float:
    """The simulated probe's small-amplitude resonance at ``theta0_rad`` in the present supply
    field: where the paper's tuning leaves the drive. The stage is turned there first (between
    cycles, the coils off); the cycle's own turn then finds it there."""
    device.set_orientations([theta0_rad])
    return float(device.expected_frequencies_hz()[0])


class _NominalFits:
    """The measurement ring-downs announced on the stream, cut and fitted as the estimator fits
    them with the lever-aware pickup of the ``nominal`` probe seen by ``pair``."""

    def __init__(self, pair, nominal: Probe):
        self.pair, self.nominal = pair, nominal
        self.assembler = SegmentAssembler(SEGMENT_BUFFER_S)
        self._fits: list = []

    def block(self, block) -> None:
        self._fits += [self._fit(segment) for segment in self.assembler.add_block(block.samples)]

    def event(self, event: PhaseEvent) -> None:
        if event.phase == Phase.RINGDOWN and not event.tuning:
            window = RingdownWindow(
                event.stamp_ns,
                event.planned_duration_s,
                event.cycle_id,
                event.repeat_index,
                event.theta0_rad,
                event.frequency_hz,
                event.tuning,
                event.probe_ids,
                event.probe_frequency_hz,
                event.probe_theta0_rad,
            )
            self._fits += [self._fit(segment) for segment in self.assembler.announce(window)]

    def take(self) -> list:
        """The fits made since the last call."""
        fits, self._fits = self._fits, []
        return fits

    def _fit(self, segment):
        own = ProbeEntry(0, self.nominal, self.nominal.f00_hz)
        lines = [
            p.entry.line(p.theta0_rad, self.pair, "difference", p.tone_hz)
            for p in window_probes((own,), segment.window)
            if p.entry
        ]
        (fit,) = fit_segment(segment, lines, COIL_OFF_SKIP_S, FitOptions(theta_stop_rad=self.nominal.theta_stop_rad))
        return fit


def compare_with_truth(calibration, truth: Probe) -> str:
    rows = [
        ("f00_hz", truth.f00_hz),
        ("beta0_hz_per_t", truth.beta0_hz_per_t),
        ("spring_nm_per_rad", truth.spring_nm_per_rad),
        ("inertia_kgm2", truth.inertia_kgm2),
        ("lever_m", truth.lever_m),
    ]
    lines = ["calibrated against true constants:"]
    for name, true in rows:
        value, std = calibration.value(name), calibration.std(name)
        lines.append(
            f"  {name:18s} {value:.6g} ± {std:.2g}  true {true:.6g}  "
            f"({(value / true - 1) * 100:+.4f} %, {(value - true) / std:+.2f} σ)"
        )
    return "\n".join(lines)
