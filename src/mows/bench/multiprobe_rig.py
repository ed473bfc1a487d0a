"""Cycles of several probes excited together, cut and fitted jointly, in device time, without ROS.

The sibling of :class:`mows.bench.rig.DeviceTimeRig` for a scene with several probes. One
cycle turns every probe to its θ0 (:meth:`mows.sim.simulator.SimulatedDevice.set_orientations`), lets them settle,
plans the multi-tone excitation (:func:`mows.physics.multitone.plan_excitation`: each probe's
tone at its f00, the cap on the summed peak, overlapping tones refused with the reason) and
excites its groups in turn under the duty limit (:class:`mows.device.cycle.tone_groups.GroupSequence`).
After each group's excitation it announces the ring-down window at the coils' switch-off, as the
driver does, cuts it from the stream (:class:`mows.estimate.segments.SegmentAssembler`) and fits
the group's probes jointly (:func:`mows.estimate.joint_segment.fit_joint_segment`). Stretches
nobody records (settling, waiting for the duty limit) are integrated without reading the sensors.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
from numpy.typing import ArrayLike

from mows.device.cycle.duty import DutyCycleLimit
from mows.device.cycle.tone_groups import DEFAULT_SWING_RAD, GroupSequence, plan_probes
from mows.estimate.joint_segment import fit_joint_segment, probe_lines
from mows.estimate.ringdown import COIL_OFF_SKIP_S, RingdownFit
from mows.estimate.segments import RingdownWindow, SegmentAssembler
from mows.records.stamps import NS_PER_S
from mows.sim.simulator import SimulatedDevice

BUFFER_S = 5.0  # the assembler keeps this much of the stream


@dataclasses.dataclass(frozen=True)
class MultiProbeSettings:
    """One cycle: the swing each probe's tone aims at (:func:`mows.physics.multitone.tone_for_swing`), the
    excitation and recorded ring-down times, the settling after the probes turn (turn_settle_s), the duty
    limit (fraction of a window) and the samples skipped after the coils' switch-off."""

    swing_rad: float = DEFAULT_SWING_RAD
    excite_s: float = 0.5
    ringdown_s: float = 0.5
    turn_settle_s: float = 0.5
    max_duty_cycle: float = 0.5
    duty_window_s: float = 10.0
    coil_off_skip_s: float = COIL_OFF_SKIP_S


@dataclasses.dataclass(frozen=True)
class MultiProbeCycle:
    """What one cycle measured: each excited probe's fit (``fits``, in probe order, each with its
    ``probe_id``), the probes refused with the reason, and the device time it ended at."""

    theta0_rad: np.ndarray
    fits: tuple[RingdownFit, ...]
    refused: tuple[tuple[int, str], ...]
    end_s: float


class MultiProbeRig:
    """``scenario``'s probes (:attr:`mows.sim.scenario.Scenario.probes`) driven by cycles of
    ``settings`` on the simulated device; probe ids are the probes' indices in the scene."""

    def __init__(self, scenario, settings: MultiProbeSettings = MultiProbeSettings(), seed: int | None = None):
        self.scenario = scenario
        self.settings = settings
        rng = np.random.default_rng(scenario.seed if seed is None else seed)
        self.device = SimulatedDevice(scenario, rng)
        self.fs = self.device.sample_rate_hz
        self.assembler = SegmentAssembler(BUFFER_S)
        self.duty = DutyCycleLimit(settings.max_duty_cycle, round(settings.duty_window_s * self.fs))
        self.peak_current_a = 0.0

    @property
    def time_s(self) -> float:
        """Device time so far."""
        return self.device.sample_index / self.fs

    def home_orientations_rad(self) -> np.ndarray:
        return np.array([p.pose.theta0_rad for p in self.scenario.placed_probes()])

    def run_cycle(self, theta0_rad: ArrayLike) -> MultiProbeCycle:
        """Turn the probes to ``theta0_rad`` (one per probe), excite them and fit their ring-downs."""
        settings, device = self.settings, self.device
        device.set_orientations(theta0_rad)
        device.idle(settings.turn_settle_s)
        plan = plan_probes(device.placed, device.setup, settings.excite_s, settings.swing_rad)
        sequence = GroupSequence(plan, device.setup, self.duty, self.fs)
        fits: list[RingdownFit] = []
        while (excitation := sequence.next(device.sample_index)) is not None:
            device.idle((excitation.on_index - device.sample_index) / self.fs)
            device.drive(excitation.tones, excitation.off_index)
            self._record(excitation.off_index - device.sample_index)
            sequence.switched(excitation.on_index, excitation.off_index)
            members = [t.probe_id for t in excitation.tones]
            window = RingdownWindow(
                round(excitation.off_index * NS_PER_S / self.fs),
                settings.ringdown_s,
                theta0_rad=float(device.placed[members[0]].pose.theta0_rad),
                excitation_frequency_hz=float(excitation.tones[0].frequency_hz),
            )
            self.assembler.announce(window)
            segments = self._record(math.ceil(settings.ringdown_s * self.fs))
            lines = probe_lines(
                self.scenario.sensors.pair,
                [device.placed[k] for k in members],
                members,
                [t.frequency_hz for t in excitation.tones],
            )
            for segment in segments:
                fits += fit_joint_segment(segment, lines, settings.coil_off_skip_s)
        fits.sort(key=lambda fit: fit.probe_id)
        return MultiProbeCycle(np.asarray(theta0_rad, float), tuple(fits), plan.refused, self.time_s)

    def _record(self, n_samples: int) -> list:
        """Read ``n_samples`` into the assembler; the segments they complete."""
        block = self.device.read(n_samples)
        if block.currents_a.size:
            self.peak_current_a = max(self.peak_current_a, float(np.max(np.abs(block.currents_a))))
        return self.assembler.add_block(block.samples)
