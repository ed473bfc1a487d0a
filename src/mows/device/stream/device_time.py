"""The driver's cycle sequencer on the simulated device, in device time: no threads, no ROS.

:class:`DeviceTimeLoop` runs :class:`mows.device.cycle.sequencer.CycleSequencer` (its duty-cycle
limit, current cap, tuning and faults) on the simulated device of a scene, with commands at exact
samples (:class:`mows.device.simulated.scheduled.ScheduledDevice`: one probe, or a scene's
probes on one shared stage). It reads the device in pieces as the sim backend does, feeds each block to
the sequencer and carries out the steps it returns (commands scheduled, their results fed back,
coils off at once), handing every block and phase event to its listeners. The device's clock is
the only clock: a run takes as long as the simulator needs, not as long as the device would.
Stretches nobody records (a gap, the probes settling) are integrated without reading the
sensors. The static-field supply is ramped on the same clock (:meth:`DeviceTimeLoop.ramp_supply`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from mows.device.cycle.phases import CycleOutcome, CycleRequest, CycleSettings, CycleStep, Phase, PhaseEvent, TuningFit
from mows.device.cycle.sequencer import CycleSequencer
from mows.device.interface import Command, CommandResult
from mows.device.simulated.scheduled import ScheduledDevice
from mows.physics.coils import CurrentCap
from mows.sim.readings import SimulatedBlock
from mows.sim.simulator import SimulatedDevice

CHUNK_S = 0.025  # samples are read in pieces of this, as the sim backend does

Block = SimulatedBlock


def scheduled_device(scenario, cap: CurrentCap, rng: np.random.Generator) -> ScheduledDevice:
    """``scenario``'s simulated device with commands at exact samples: its probes on one shared
    stage (:attr:`mows.sim.scenario.Scenario.probes`, one or several)."""
    return ScheduledDevice(SimulatedDevice(scenario, rng), cap)


class DeviceTimeLoop:
    """Cycles of ``settings`` on ``device`` (module docstring), its coils capped by the device's
    cap; ``fit`` retunes the excitation of a probe that has the coils to itself, from its f00.
    ``on_block`` hears every block read and ``on_event`` every phase announced, in the order
    the device produced them."""

    def __init__(
        self,
        device: ScheduledDevice,
        settings: CycleSettings,
        *,
        fit: TuningFit,
        on_block: Callable[[Block], None] = lambda block: None,
        on_event: Callable[[PhaseEvent], None] = lambda event: None,
    ):
        self.device = device
        self.fs = device.device.sample_rate_hz
        scenario = device.device.scenario
        self.sequencer = CycleSequencer(
            settings, scenario.setup, device.cap, self.fs, scenario.probe.f00_hz, fit=fit, probes=device.home
        )
        self.on_block, self.on_event = on_block, on_event
        self._chunk = max(1, round(CHUNK_S * self.fs))
        self._results: list[CommandResult] = []
        self._outcome: CycleOutcome | None = None
        self._idle_until = 0
        # The sequencer anchors its clock on the first samples.
        self.first_block = self.read(self._chunk)[0]

    @property
    def time_s(self) -> float:
        """Device time so far."""
        return self.device.next_index / self.fs

    def run_cycle(self, request: CycleRequest) -> CycleOutcome:
        """One cycle to its end (ValueError, with the reason, if it cannot start)."""
        self._outcome = None
        self._act(self.sequencer.start(request))
        while self._outcome is None:
            if self._idle_until > self.device.next_index:
                self.device.idle_until(self._idle_until)
                self._idle_until = 0
            self.read(self._chunk)
        return self._outcome

    def ramp_supply(self, current_a: float, settle_s: float) -> str:
        """Ramp the static-field supply to ``current_a`` and read on until ``settle_s`` after it
        got there; '' once there, else the device's reason for refusing it."""
        try:
            reached = self.device.schedule_field_current(self.device.next_index, current_a)
        except ValueError as refused:
            return str(refused)
        end = reached + 1 + round(settle_s * self.fs)
        while self.device.next_index < end:
            self.read(min(self._chunk, end - self.device.next_index))
        return ""

    def read(self, n_samples: int) -> list[Block]:
        """Read ``n_samples`` (cut where commands apply), each block to the listener and the sequencer."""
        blocks: list[Block] = list(self.device.read_until(self.device.next_index + n_samples))
        for block in blocks:
            self.on_block(block)
            self._act(self.sequencer.on_samples(block.samples))
        return blocks

    def _act(self, step: CycleStep) -> None:
        steps = [step]
        while steps:
            step = steps.pop(0)
            if step.coils_off_now:
                self.device.switch_off_at(self.device.next_index)
            for command in step.commands:
                self._results.append(self._send(command))
            for event in step.events:
                self._event(event)
            if step.outcome is not None:
                self._outcome = step.outcome
            results, self._results = self._results, []
            steps += [self.sequencer.on_result(result) for result in results]

    def _send(self, command: Command) -> CommandResult:
        """Schedule ``command`` on the device; its result (refused with the reason, never raised)."""
        try:
            applied = self.device.schedule(command)
        except (RuntimeError, ValueError) as refused:
            return CommandResult(command.command_id, False, reason=str(refused))
        return CommandResult(command.command_id, True, applied)

    def _event(self, event: PhaseEvent) -> None:
        if event.phase in (Phase.GAP, Phase.SETTLING) and event.planned_duration_s > 0:
            # Nobody records these samples: the probe moves on without its sensors being read.
            self._idle_until = event.sample_index + round(event.planned_duration_s * self.fs)
        self.on_event(event)
