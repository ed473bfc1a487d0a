"""What a device is to the driver, whatever is behind it (the simulator, a serial link, a bag).

The driver sends commands that take effect at a device sample index and learns, from a
:class:`CommandResult`, the sample at which each one did (or why it was refused). It polls
for what the device has sent since: :class:`~mows.records.samples.SampleBlock` runs of consecutive samples
stamped on the device clock, command results, and :class:`LinkEvent` changes of the link.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Sequence

from mows.device.protocol.payloads import DeviceInfo
from mows.physics.coils import CoilSetup, CurrentCap
from mows.physics.coupling import PlacedProbe
from mows.physics.multitone import Tone, coil_amplitudes_a
from mows.physics.pose import Pose
from mows.physics.probe import PAPER_PROBE
from mows.physics.supply import SupplyLimits


@dataclasses.dataclass(frozen=True)
class CoilTone:
    """One probe's share of a coil drive: probe ``probe_id`` driven at ``frequency_hz`` with a
    signed peak current per coil, ``amplitudes_a``."""

    probe_id: int
    frequency_hz: float
    amplitudes_a: tuple[float, ...]


def coil_tones(setup: CoilSetup, tones: Sequence[Tone]) -> tuple[CoilTone, ...]:
    """The coil currents of ``tones`` (:class:`mows.physics.multitone.Tone`) in ``setup``'s scheme,
    one CoilTone each (ValueError if one alone is above the setup's cap)."""
    rows = coil_amplitudes_a(setup, tones)
    return tuple(CoilTone(t.probe_id, t.frequency_hz, tuple(float(a) for a in row)) for t, row in zip(tones, rows))


@dataclasses.dataclass(frozen=True)
class CoilCommand:
    """Drive the coils with the sum of ``tones`` from device sample ``at_sample_index`` on, every
    tone's time counted from switch-on: one probe's drive is one tone, several probes excited at
    once one tone each. No tones (or all of zero current) switches every tone off at once.
    ``samples``: how long the drive lasts, its cap held on the summed peak over those samples
    (0: until the next coil command, the cap on each coil's summed amplitude)."""

    command_id: int
    at_sample_index: int
    tones: tuple[CoilTone, ...] = ()
    samples: int = 0

    @property
    def off(self) -> bool:
        return not any(any(t.amplitudes_a) for t in self.tones)


@dataclasses.dataclass(frozen=True)
class OrientationCommand:
    """Turn the probe (the rotation stage) to ``theta0_rad`` at device sample ``at_sample_index``;
    ``by_hand``: the operator has turned it there and confirmed it (a stage without a motor
    takes no other turn)."""

    command_id: int
    at_sample_index: int
    theta0_rad: float
    by_hand: bool = False


@dataclasses.dataclass(frozen=True)
class FieldCurrentCommand:
    """Ramp the static-field supply (:mod:`mows.physics.supply`) to ``current_a`` from device
    sample ``at_sample_index`` on, within its slew limit; the result's ``applied_sample_index``
    is the sample at which the ramp reaches the (resolution-rounded) target."""

    command_id: int
    at_sample_index: int
    current_a: float


Command = CoilCommand | OrientationCommand | FieldCurrentCommand


def energises(command: Command) -> bool:
    """Whether ``command`` puts current through a coil: a coil drive, or a supply current other than zero."""
    if isinstance(command, CoilCommand):
        return not command.off
    return isinstance(command, FieldCurrentCommand) and command.current_a != 0.0


@dataclasses.dataclass(frozen=True)
class CommandResult:
    """The device's answer to command ``command_id``: the sample it applies at, or why not."""

    command_id: int
    accepted: bool
    applied_sample_index: int = -1
    reason: str = ""


@dataclasses.dataclass(frozen=True)
class LinkEvent:
    """The link to the device came up (the device answered) or went down, and why."""

    up: bool
    reason: str


@dataclasses.dataclass(frozen=True)
class DeviceFault:
    """The device switched its coils off by itself (its watchdog): a running cycle is void."""

    reason: str


class NotExciting(RuntimeError):
    """A command to a device that cannot take it now (a recording, a link that is down)."""


class Backend(abc.ABC):
    """Where the driver's samples come from and its commands go to.

    ``supply_limits`` is the static-field supply's cap, slew, resolution and polarity when the
    backend drives one it knows (None: no supply, or a device's own that does not say).
    ``info`` describes the device once it is known (None before a serial device answers);
    ``probes`` are the probes its stage carries, at their home orientations (one or several;
    several are driven one tone each): the paper's probe at the coils' centre for a device that
    does not say (a serial device, the bench), and ``coils`` are its coils where they stand
    among those probes, in the same frame: how hard a tone swings a probe depends on where the
    probe sits in the coils' field, which a coil setup known by name does not say (None: the
    driver's coil setup, by name). ``command_lead_samples`` is how far ahead
    of the newest received sample a command must be scheduled to reach the device in time (a
    late one applies at the device's next sample, and its result says which).
    """

    name: str
    can_excite: bool
    supply_limits: SupplyLimits | None = None  # the field supply's range and limits, if known
    probes: tuple[PlacedProbe, ...] = (PlacedProbe(PAPER_PROBE, Pose()),)  # on its stage, at home
    coils: CoilSetup | None = None  # the coils among ``probes``, in their frame; None: the named setup

    # Read-only for the driver: a serial device's info and lead follow its link.
    @property
    @abc.abstractmethod
    def info(self) -> DeviceInfo | None: ...

    @property
    def command_lead_samples(self) -> int:
        return 0

    @abc.abstractmethod
    def poll(self, timeout_s: float) -> list:
        """What the device sent since the last poll (SampleBlock, CommandResult, LinkEvent,
        DeviceFault and, from a recording, the recorded cycle.PhaseEvent), waiting up to
        ``timeout_s`` for something to arrive."""

    @abc.abstractmethod
    def send(self, command: Command) -> None:
        """Queue ``command``; its CommandResult arrives through ``poll``. ValueError for a coil
        current above the cap (nothing is sent); NotExciting when the device cannot take it."""

    @abc.abstractmethod
    def coils_off_now(self) -> None:
        """Switch the coils off at the device's next sample and cancel every waiting command.
        Never raises: when the link is down the device's watchdog has switched them off."""

    @abc.abstractmethod
    def supply_to_zero_now(self) -> None:
        """Ramp the static-field supply to zero from the device's next sample, dropping any
        ramp that waits. Never raises: when the link is down the device's watchdog ramps it down."""

    @abc.abstractmethod
    def stats(self) -> dict:
        """Counters and state for /diagnostics: always ``link`` (a word), more by backend."""

    @abc.abstractmethod
    def close(self) -> None:
        """Coils off and the supply to zero, then release the device."""

    def closed_state(self) -> str:
        """What the device was left in by ``close``, as read back from it, for the log; '' when
        it has nothing read back to say."""
        return ""


def one_tone(command: CoilCommand, device: str, n_coils: int) -> tuple[float, tuple[float, ...]]:
    """The frequency and the coil currents of ``command`` for a ``device`` of ``n_coils`` coils
    that drives one tone at a time (zeros: off); ValueError for several tones."""
    if command.off:
        return 0.0, (0.0,) * n_coils
    if len(command.tones) > 1:
        raise ValueError(
            f"the {device} drives one tone at a time: a multi-tone excitation of several probes is refused"
        )
    (tone,) = command.tones
    return tone.frequency_hz, tone.amplitudes_a


def check_coil_currents(amplitudes_a: Sequence[float], info: DeviceInfo, cap_a: float) -> None:
    """ValueError if ``amplitudes_a`` has the wrong number of coils or a current above ``cap_a``
    or the device's own cap: such a command is never sent."""
    if len(amplitudes_a) != info.n_coils:
        raise ValueError(f"{len(amplitudes_a)} coil amplitudes given; the device has {info.n_coils} coils")
    CurrentCap(min(cap_a, info.current_cap_a)).check(amplitudes_a)
