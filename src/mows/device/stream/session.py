"""A driver session: one backend, the cycle sequencer and the block assembler, driven by one
streaming thread, with cycles and the emergency stop requested from other threads.

The streaming thread calls :meth:`DeviceSession.step` in a loop and publishes what it
returns (blocks, phase events) in order. Requests from other threads (a cycle, the emergency
stop, a supply current) take the session's lock, act on the device at once (the emergency stop switches the
coils off before it returns) and leave their phase events for the next ``step`` to publish.
A request that sends commands (a cycle, a supply current) first waits until the samples a
poll in flight has read are taken: a command is scheduled at the newest sample taken, and
its answer is awaited for ``confirm_timeout_s`` of device samples from there, so samples the
device sent before the command went out must be taken before it goes. Otherwise, after the
streaming thread stalled, one poll holds more than that, and a cycle fails for an answer the
device gave at once.
In tracking mode (:mod:`mows.device.cycle.tracking`) ``step`` starts the next tracking cycle whenever
none runs.

The session is *armed* (:meth:`DeviceSession.arm`) only while the driver may energise a coil
(its lifecycle state ``active``): disarmed, it refuses cycles and supply currents, starts no
tracking cycle, and the one place that sends commands to the device (``_act``) refuses to send
any that would drive a coil, so no bug upstream can switch one on. :meth:`DeviceSession.disarm`
switches the coils off at the device's next sample, fails a running cycle and ramps the supply
to zero. Nothing here knows about ROS.

One module of more than 450 lines: the lock, the poll in flight and the requests that wait for
it are one ordering rule, which split across files would have to be read in two places.
"""

from __future__ import annotations

import dataclasses
import threading
import time
from collections.abc import Callable

from mows.device.cycle.phases import (
    CycleOutcome,
    CycleRequest,
    CycleSettings,
    CycleStep,
    Phase,
    PhaseEvent,
    SupplyEvent,
    TuningFit,
)
from mows.device.cycle.sequencer import CycleSequencer
from mows.device.cycle.tracking import TrackingLoop, TrackingSettings
from mows.device.interface import (
    Backend,
    Command,
    CommandResult,
    DeviceFault,
    LinkEvent,
    energises,
)
from mows.device.stream.blocks import BlockAssembler
from mows.device.stream.rate import RateMeter
from mows.device.stream.supply_ramps import SupplyRamps
from mows.physics.coils import CoilSetup, CurrentCap
from mows.records.samples import SampleBlock

STALL_TIMEOUT_S = 2.0  # a running cycle fails when no samples arrive for this long (host time)


@dataclasses.dataclass
class Output:
    """What one step produced, in the order it is to be published."""

    blocks: list[SampleBlock] = dataclasses.field(default_factory=list)
    events: list[PhaseEvent] = dataclasses.field(default_factory=list)
    supply: list[SupplyEvent] = dataclasses.field(default_factory=list)  # the supply's ramps, in order
    links: list[LinkEvent] = dataclasses.field(default_factory=list)  # for the log, in any state


@dataclasses.dataclass(frozen=True)
class SessionConfig:
    block_duration_s: float
    settings: CycleSettings
    setup: CoilSetup  # the coils by name (a device that knows where they stand brings its own)
    cap: CurrentCap
    frequency_hz: float  # a first resonance estimate, of the probe whose f00 is nearest it
    fit: TuningFit  # fits the tuning ring-downs (the estimator's fit_tuning)
    # A session that follows another on the same device link (the driver reconfigured) goes on
    # from where it left: the next device clock's epoch, and cycle ids not used before.
    first_epoch: int = 0
    last_cycle_id: int = 0


class DeviceSession:
    """``backend`` streamed into blocks; cycles run by a :class:`CycleSequencer` built once the
    device is known (a serial device describes itself when it answers)."""

    def __init__(
        self,
        backend: Backend,
        config: SessionConfig,
        monotonic: Callable[[], float] = time.monotonic,
        *,
        armed: bool = False,
    ):
        self.backend = backend
        self.armed = armed  # whether a coil may be energised (the driver is active)
        self.disarmed_reason = "" if armed else "the session is not armed"
        self.config = config
        self.sequencer: CycleSequencer | None = None
        self.assembler: BlockAssembler | None = None
        self.link_up = backend.info is not None
        self.link_changes = 0
        self.last_link_reason = ""
        self.refused_commands = 0
        self.device_faults = 0
        self.last_device_fault = ""
        self._monotonic = monotonic
        self._lock = threading.RLock()
        self._polling = False  # the streaming thread reads the device outside the lock
        self._waiting = 0  # requests that wait for what the poll in flight read to be taken
        self._polled = threading.Condition(self._lock)  # notified when either ends
        self._events: list[PhaseEvent] = []
        self._replayed_phase: Phase | None = None
        self.stage_angle_rad: float | None = None  # where the rotation stage stands, once known
        self._on_done: Callable[[CycleOutcome], None] | None = None
        self.tracking = TrackingLoop()
        self._last_samples_s = monotonic()
        self._rate = RateMeter()  # the achieved sample rate
        self._next_index = 0  # the sample after the newest received
        self.supply = SupplyRamps(self._stamp_ns)  # the static-field supply's ramps (mows.device.stream.supply_ramps)
        self._anchor: tuple[int, int, float] | None = None  # (sample index, stamp ns, rate) of the newest block
        if backend.info is not None:
            self._device_known()

    # --- the streaming thread --------------------------------------------------------------
    def step(self, timeout_s: float) -> Output:
        """Poll the backend once (up to ``timeout_s``) and act on what came."""
        with self._lock:
            # A request that waited for the last poll goes first: else this poll could read
            # before its command goes out, each time (the lock is not fair).
            self._polled.wait_for(lambda: not self._waiting)
            self._polling = True
        try:
            items = self.backend.poll(timeout_s)
        except BaseException:
            self._poll_taken()
            raise
        with self._lock:
            self._poll_taken()  # the requests it wakes need this lock: they go on after the take
            output = Output()
            for item in items:
                self._take(item, output)
            if (
                self.sequencer is not None
                and self.sequencer.busy
                and self._monotonic() - self._last_samples_s > STALL_TIMEOUT_S
            ):
                self._act(self.sequencer.abort(f"no samples from the device for {STALL_TIMEOUT_S:g} s"))
            self._track()
            output.events += self._events
            output.supply += self.supply.take_events()
            self._events = []
            for event in output.events:
                if event.cycle_id:  # a cycle's phases begin once the stage has turned to its θ0
                    self.stage_angle_rad = event.theta0_rad
            return output

    def _poll_taken(self) -> None:
        with self._lock:
            self._polling = False
            self._polled.notify_all()

    def _after_poll(self) -> None:
        """Wait (in a request, holding the lock) until what a poll in flight read is taken.
        Every backend's poll returns within its timeout, so the wait is one poll's."""
        self._waiting += 1
        try:
            self._polled.wait_for(lambda: not self._polling)
        finally:
            self._waiting -= 1
            self._polled.notify_all()

    def _take(self, item, output: Output) -> None:
        if isinstance(item, SampleBlock):
            self._count_arrival(len(item))
            # Samples come from a known device: its link-up (which builds the assembler) precedes them.
            assert self.assembler is not None
            self._next_index = item.first_sample_index + len(item)
            self._anchor = (item.first_sample_index, item.stamp_ns, item.sample_rate_hz)
            self.supply.reached(self._next_index)
            output.blocks += self.assembler.add(item)
            if self.sequencer is not None:
                self._act(self.sequencer.on_samples(item))
        elif isinstance(item, CommandResult) and self.supply.answers(item):
            self.refused_commands += not item.accepted
            self.supply.answered(item, self._next_index)
        elif isinstance(item, CommandResult):
            self.refused_commands += not item.accepted
            assert self.sequencer is not None  # results answer commands: the sequencer's, supply ones apart
            self._act(self.sequencer.on_result(item))
        elif isinstance(item, LinkEvent):
            self._link(item)
            output.links.append(item)
        elif isinstance(item, SupplyEvent):  # replayed from a recording
            self.supply.event(item)
        elif isinstance(item, DeviceFault):
            self.device_faults += 1
            self.last_device_fault = item.reason
            if self.sequencer is not None:
                self._act(self.sequencer.abort(item.reason))
        else:  # a PhaseEvent replayed from a recording: the phase the recording is in
            self._events.append(item)
            self._replayed_phase = item.phase

    def _link(self, event: LinkEvent) -> None:
        self.link_up, self.last_link_reason = event.up, event.reason
        self.link_changes += 1
        if event.up:
            if self.assembler is None:
                self._device_known()
            # Whatever the device did while we were away, its coils go off now.
            self.backend.coils_off_now()
        if self.sequencer is not None:
            self._act(self.sequencer.on_link(event))

    def _device_known(self) -> None:
        info = self.backend.info
        assert info is not None  # called once the device has described itself (at start or on link up)
        self.assembler = BlockAssembler(
            round(self.config.block_duration_s * info.sample_rate_hz), self.config.first_epoch
        )
        c, lead = self.config, self.backend.command_lead_samples
        if not self.backend.can_excite:
            return
        # Tones are sized by the coils where the device has them among its probes, if it says.
        setup = c.setup if self.backend.coils is None else self.backend.coils
        self.sequencer = CycleSequencer(
            c.settings,
            setup,
            c.cap,
            info.sample_rate_hz,
            c.frequency_hz,
            lead,
            fit=c.fit,
            probes=self.backend.probes,
            last_cycle_id=c.last_cycle_id,
        )

    def _count_arrival(self, n: int) -> None:
        self._last_samples_s = self._monotonic()
        self._rate.add(self._last_samples_s, n)

    def _act(self, step: CycleStep) -> None:
        """Carry out what the sequencer asked for."""
        if step.coils_off_now:
            self.backend.coils_off_now()
        for command in step.commands:
            try:
                self._check_armed(command)
                self.backend.send(command)
            except (ValueError, RuntimeError) as refused:
                # Refused before it left (the cap, a link that is down): the cycle learns why,
                # fails, and the rest of its commands are not sent.
                assert self.sequencer is not None  # the commands came from the sequencer
                self._act(self.sequencer.on_result(CommandResult(command.command_id, False, reason=str(refused))))
                break
        self._events += step.events
        if step.outcome is not None and self._on_done is not None:
            done, self._on_done = self._on_done, None
            done(step.outcome)

    def _track(self) -> None:
        """Start the next tracking cycle once the sequencer is idle (:mod:`mows.device.cycle.tracking`)."""
        s = self.sequencer
        if s is None or s.busy or not self.tracking.on or not self.armed or not self.link_up or s.next_index == 0:
            return
        request = self.tracking.next_request(self.config.settings)
        assert request is not None  # tracking is on
        try:
            step = s.start(request)
        except ValueError as refused:  # a latched stop, a kick over the cap or beyond the duty limit
            self.tracking.stop(f"tracking stopped: {refused}")
            return
        self._on_done = self.tracking.on_outcome
        self._last_samples_s = self._monotonic()
        self._act(step)

    def _check_armed(self, command: Command) -> None:
        """ValueError for a command that would energise a coil while the session is disarmed."""
        if energises(command) and not self.armed:
            raise ValueError(f"coils may not be energised: {self.disarmed_reason}")

    # --- requests from other threads -------------------------------------------------------
    def arm(self) -> None:
        """Allow cycles and supply currents (the driver became active)."""
        with self._lock:
            self.armed, self.disarmed_reason = True, ""

    def disarm(self, reason: str) -> None:
        """Refuse cycles and supply currents from now on, for ``reason``: the coils go off at the
        device's next sample, a running cycle fails and the supply ramps to zero."""
        with self._lock:
            self.armed, self.disarmed_reason = False, reason
            if self.sequencer is not None:  # a deactivation is no fault of the cycle's
                self._act(self.sequencer.cancel(reason))
            self.backend.coils_off_now()
            self.backend.supply_to_zero_now()

    def start_cycle(self, request: CycleRequest, on_done: Callable[[CycleOutcome], None]) -> int:
        """Start a cycle; ``on_done(outcome)`` is called (from the streaming thread, or from the
        thread that stops it) when it ends. Returns its cycle id; ValueError if it cannot run."""
        with self._lock:
            self._after_poll()
            if self.sequencer is None:
                raise ValueError(
                    f"the {self.backend.name} backend cannot run cycles"
                    if not self.backend.can_excite
                    else self._not_answered()
                )
            if not self.armed:
                raise ValueError(self.disarmed_reason)
            if not self.link_up:
                raise ValueError(f"the link to the device is down ({self.last_link_reason})")
            if self.tracking.on:
                raise ValueError("tracking mode is on: switch it off (parameter tracking) before a cycle")
            step = self.sequencer.start(request)
            self._on_done = on_done
            self._last_samples_s = self._monotonic()
            self._act(step)
            return self.sequencer.last_cycle_id

    @property
    def epoch(self) -> int:
        """The device clock's epoch of the newest samples (:class:`BlockAssembler`)."""
        return self.config.first_epoch if self.assembler is None else self.assembler.epoch

    def cancel_cycle(self, cycle_id: int, reason: str) -> bool:
        """End cycle ``cycle_id`` if it is the one running (coils off at the device's next
        sample; its ``on_done`` hears it failed, cancelled for ``reason``); whether it was."""
        with self._lock:
            s = self.sequencer
            if s is None or not s.busy or s.last_cycle_id != cycle_id:
                return False
            self._act(s.cancel(reason))
            return True

    def set_tracking(self, settings: TrackingSettings | None) -> None:
        """Track with ``settings`` from the next idle moment on; None: no tracking cycle after the running one."""
        with self._lock:
            if settings is None:
                if self.tracking.on:
                    self.tracking.stop("tracking is off")
            else:
                self.tracking.start(settings)

    def set_field_current(self, current_a: float, on_done: Callable[[CommandResult], None]) -> int:
        """Ramp the static-field supply to ``current_a``; ``on_done(result)`` is called (from the
        streaming thread) once the device refused it or its samples have reached the ramp's
        end. Returns the command id; ValueError if it cannot be sent (no supply, above the cap,
        no device)."""
        with self._lock:
            self._after_poll()
            if not self.backend.can_excite:
                raise ValueError(f"the {self.backend.name} backend has no supply to set")
            if not self.link_up:
                raise ValueError(f"the link to the device is down ({self.last_link_reason})")
            command = self.supply.command(self._next_index + self.backend.command_lead_samples, current_a)
            self._check_armed(command)
            self.backend.send(command)
            self.supply.sent(command, on_done)
            return command.command_id

    def supply_to_zero(self, reason: str = "supply to zero") -> None:
        """Ramp the supply to zero now, dropping any ramp that waits (a cancelled calibration)."""
        with self._lock:
            self.backend.supply_to_zero_now()
            self.supply.dropped(self._next_index, reason)

    def _stamp_ns(self, sample_index: int) -> int:
        """The device stamp of a sample, from the newest block (0 before any block came)."""
        if self._anchor is None:
            return 0
        index, stamp_ns, rate_hz = self._anchor
        return stamp_ns + round((sample_index - index) * 1e9 / rate_hz)

    def _not_answered(self) -> str:
        """Why no cycle can run on a device that has never described itself."""
        why = self.last_link_reason or self.backend.stats().get("last_error") or "no answer to Hello yet"
        return f"the device has not answered yet ({why})"

    def emergency_stop(self, engage: bool, reason: str) -> bool:
        """Engage (coils off at once, the supply ramped to zero, latch) or release; returns
        whether it is latched."""
        with self._lock:
            if engage:
                self.tracking.stop(f"tracking stopped by the emergency stop: {reason or 'no reason given'}")
                self.backend.coils_off_now()
                self.backend.supply_to_zero_now()
                self.supply.dropped(self._next_index, f"emergency stop: {reason or 'no reason given'}")
            if self.sequencer is None:
                return False
            self._act(self.sequencer.emergency_stop(reason) if engage else self.sequencer.release())
            return self.sequencer.latched is not None

    def set_block_duration(self, block_duration_s: float) -> None:
        with self._lock:
            self.config = dataclasses.replace(self.config, block_duration_s=block_duration_s)
            if self.assembler is not None:
                info = self.backend.info
                assert info is not None  # the assembler is built once the device is known, which it stays
                self.assembler.block_samples = round(block_duration_s * info.sample_rate_hz)

    def set_cycle_settings(self, settings: CycleSettings) -> None:
        """Settings for the next cycle (a running one keeps its own)."""
        with self._lock:
            self.config = dataclasses.replace(self.config, settings=settings)
            if self.sequencer is not None:
                self.sequencer.settings = settings

    def close(self) -> str:
        """Coils off, the supply ramped to zero and the device released; a running cycle fails.
        What the device was left in, as read back from it ('' when it reads nothing back)."""
        with self._lock:
            self.tracking.stop("the driver is shutting down")
            if self.sequencer is not None and self.sequencer.busy:
                self._act(self.sequencer.abort("the driver is shutting down"))
            self.backend.close()
            return self.backend.closed_state()

    # --- state -----------------------------------------------------------------------------
    def achieved_rate_hz(self) -> float | None:
        """The achieved sample rate (:class:`mows.device.stream.rate.RateMeter`); None while not yet known."""
        with self._lock:
            return self._rate.rate_hz(self._monotonic())

    def health(self) -> dict:
        """Everything /diagnostics reports, as plain values."""
        with self._lock:
            values = {
                "armed": self.armed,
                "link_up": self.link_up,
                "link_changes": self.link_changes,
                "link_reason": self.last_link_reason,
                "refused_commands": self.refused_commands,
                "device_faults": self.device_faults,
                "last_device_fault": self.last_device_fault,
                **self.tracking.state(),
                **self.backend.stats(),
            }
            if (supply := self.supply.state) is not None:
                values.update(supply_state_a=supply.current_a, supply_ramping=supply.ramping)
            a, s = self.assembler, self.sequencer
            if a is not None:
                values.update(
                    samples=a.samples,
                    gaps=a.gaps,
                    missing_samples=a.missing_samples,
                    device_restarts=a.epoch,
                    saturated_samples=a.saturated_samples,
                )
            if s is None:  # a recording: the phase of its last replayed event
                replayed = self._replayed_phase  # IDLE is 0: a phase is there when it is not None
                values.update(phase="none replayed yet" if replayed is None else replayed.name)
            else:
                values.update(
                    phase=s.phase.name if s.busy or s.phase != Phase.FAULT else Phase.IDLE.name,
                    fault=s.fault,
                    cycle_running=s.busy,
                    estop_latched=s.latched is not None,
                    estop_reason=s.latched or "",
                    excitation_frequency_hz=s.frequency_hz,
                    duty_cycle=s.duty_fraction(),
                )
            return values


def continued(previous: DeviceSession | None, config: SessionConfig) -> SessionConfig:
    """``config`` for a session that follows ``previous`` on the same device link (the driver
    reconfigured): the device clock starts again, so the next epoch, and cycle ids go on from
    the last one the graph has seen."""
    if previous is None:
        return config
    last = previous.sequencer.last_cycle_id if previous.sequencer is not None else previous.config.last_cycle_id
    return dataclasses.replace(config, first_epoch=previous.epoch + 1, last_cycle_id=last)
