"""A laboratory supply that speaks SCPI, as the calibration's static-field supply: the command
set (YAML, so that another supply is a file, not code) and the thin PyVISA edge; its ramps on the
device's sample clock are :mod:`mows.device.instruments.supply_schedule`.

The paper's supply is a Rohde & Schwarz NGM202 (0.1 mA resolution, 2 A; Methods), the default
command set (``hardware/rs_ngm202.yaml``): a unipolar source (0 … +cap), so a negative current
is refused before it is sent. A supply is not on the card's sample clock: the
backend writes each step of a ramp when the input stream reaches its sample, so a step lands
within one input block of it, and reads the current back ``settle_s`` after the last one.

The supply fails safe. At open its status is cleared, its ``*IDN?`` must name the file's model
(another instrument at the address gets nothing more), its safety limits and over-voltage
protection are set from the file's caps before its output is switched on. After every command its
whole error queue is read and any entry refuses the command. On close (and on any fault) the
current is set to zero, the channel's output, every other channel's and the master output are
switched off and each is read back off, every step tried whatever the others did; on close the
instrument is then returned to local control.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import math
import string
import time
from collections.abc import Callable
from typing import Any

from mows.device.instruments.daq import HARDWARE_DIR
from mows.physics import ranges
from mows.physics.schema import load_yaml, positive, refused, typed
from mows.physics.supply import SupplyLimits

PAPER_SUPPLY_FILE = HARDWARE_DIR / "rs_ngm202.yaml"
SIMULATED_SUPPLY_FILE = HARDWARE_DIR / "ngm202_pyvisa_sim.yaml"  # the pyvisa-sim instrument
SIMULATED_RESOURCE = "TCPIP0::192.168.0.20::inst0::INSTR"  # its address in that file


MAX_ERRORS = 32  # entries read from the error queue after one command; more are said to be left
OUTPUT_STATES = {"0": "off", "OFF": "off", "1": "on", "ON": "on"}  # the answers to output_state, as SCPI allows


class SupplyError(OSError):
    """The supply is missing, refused a command, or reads back something else than was set."""


@dataclasses.dataclass(frozen=True)
class ScpiCommands:
    """What to send for each step; ``{}`` is the value, formatted as written (``CURR {:.4f}``)."""

    set_current: str = "CURR {:.4f}"
    measure_current: str = "MEAS:CURR?"
    set_voltage: str = "VOLT {:.3f}"
    output: str = "OUTP {:d}"
    query_error: str = "SYST:ERR?"
    identify: str = "*IDN?"
    select_channel: str = "INST:NSEL {:d}"  # '' for a supply of one channel
    no_error: str = "0,"  # how the answer to query_error begins when there is none
    clear_status: str = "*CLS"
    # Each of the following is '' for a model without it.
    master_output: str = "OUTP:GEN {:d}"  # the switch behind every channel's output
    current_safety_limit: str = "CURR:ALIM {:.4f}"  # the instrument refuses a current above it
    voltage_safety_limit: str = "VOLT:ALIM {:.3f}"
    safety_limits: str = "ALIM {:d}"  # the two limits above switched on
    over_voltage_level: str = "VOLT:PROT:LEV {:.3f}"
    over_voltage_protection: str = "VOLT:PROT {:d}"
    local: str = "SYST:LOC"  # the front panel back to the operator
    output_state: str = "OUTP?"  # answers 0 once the output is off: read back after switching it off
    master_output_state: str = "OUTP:GEN?"  # the master output, read back after switching it off
    protection_tripped: str = "VOLT:PROT:TRIP?"  # answers 1 once the over-voltage protection has tripped
    clear_protection: str = "VOLT:PROT:CLE"  # a tripped protection reset (the output stays off until then)

    def __post_init__(self) -> None:
        formats = {
            "set_current": 1.5,
            "set_voltage": 10.0,
            "output": 1,
            "select_channel": 1,
            "master_output": 1,
            "current_safety_limit": 1.5,
            "voltage_safety_limit": 10.0,
            "safety_limits": 1,
            "over_voltage_level": 10.0,
            "over_voltage_protection": 1,
        }
        required = ("set_current", "set_voltage", "output")  # the others are '' for a model without them
        for name, sample in formats.items():
            if name in required or getattr(self, name):
                _check_format(name, getattr(self, name), sample)


def _check_format(name: str, command: str, sample: float) -> None:
    """Refuse a command that is not one value's format (``CURR {:.4f}``): no ``{}``, several,
    a named one, or a format the value (a float, or an int for ``{:d}`` commands) cannot take.
    Checked when the file is read, not when the first current is sent."""
    kind = type(sample).__name__
    expected = f"must hold one {{}} for the value, formatting a {kind} (e.g. 'CURR {{:.4f}}')"
    try:
        fields = [field for _, field, _, _ in string.Formatter().parse(command) if field is not None]
        command.format(sample)
    except (ValueError, IndexError, KeyError) as error:
        raise refused(name, command, f"{expected}: {error}") from None
    if fields not in ([""], ["0"]):
        raise refused(name, command, expected)


@dataclasses.dataclass(frozen=True)
class ScpiSupplyConfig:
    """The supply file (docs/hardware.md): the model its ``*IDN?`` must name, its limits (cap,
    slew, resolution and polarity: ``unipolar``, 0 … cap, unless the file says ``bipolar``), the
    channel the pair is on, the voltage limit (the pair's resistance × the largest current, with
    margin), the over-voltage protection's level above it, the read-back's stated accuracy
    (± ``readback_accuracy_rel`` × I ± ``readback_accuracy_a``) and the time the current takes
    to settle after a step (the pair's inductance), and its commands."""

    cap_a: float
    slew_a_per_s: float
    resolution_a: float
    model: str  # the second field of *IDN? ("Rohde&Schwarz,NGM202,…")
    # A laboratory supply sources one sign; a file that does not say so is not trusted with the other.
    polarity: str = "unipolar"
    commands: ScpiCommands = ScpiCommands()
    channel: int = 1
    channels: int = 1  # the model's outputs: each is switched off and read back so on close
    voltage_limit_v: float = 10.0
    over_voltage_v: float = 12.0
    readback_accuracy_a: float = 1.0e-3
    readback_accuracy_rel: float = 5.0e-4
    settle_s: float = 0.1
    write_termination: str = "\n"
    read_termination: str = "\n"
    timeout_s: float = 2.0
    name: str = "scpi"
    limits: SupplyLimits = dataclasses.field(init=False, repr=False)  # of cap, slew, resolution and polarity

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "limits", SupplyLimits(self.cap_a, self.slew_a_per_s, self.resolution_a, self.polarity)
        )
        positive("voltage_limit_v", self.voltage_limit_v)  # never sent as VOLT nan, nor as a negative limit
        positive("timeout_s", self.timeout_s)
        for name, quantity in (("timeout_s", "timeout_s"), ("settle_s", "settle_s"), ("slew_a_per_s", "slew_a_per_s")):
            ranges.check(quantity, getattr(self, name), name)
        ramp_s = self.cap_a / self.slew_a_per_s
        if ramp_s > ranges.MAX_WAIT_S:
            raise ValueError(
                f"slew_a_per_s = {self.slew_a_per_s:g} A/s takes {ramp_s:.3g} s to ramp to cap_a = {self.cap_a:g} A: "
                f"beyond the {ranges.MAX_WAIT_S:g} s any wait of the bench may last"
            )
        if self.channel < 1:
            raise refused("channel", self.channel, "is not a channel number (1, 2, …)")
        if self.channels < self.channel:
            raise refused("channels", self.channels, f"must count channel {self.channel} among the model's outputs")
        if not self.model.strip():
            raise ValueError("model = '' : the supply file names the model its *IDN? must report")
        if not self.over_voltage_v > self.voltage_limit_v:
            raise ValueError(
                f"over_voltage_v = {self.over_voltage_v!r} must exceed voltage_limit_v = {self.voltage_limit_v!r} "
                "(the protection would trip at the limit itself)"
            )
        for name in ("readback_accuracy_a", "readback_accuracy_rel", "settle_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"{name} = {value!r} must be a finite number ≥ 0")

    def readback_tolerance_a(self, current_a: float) -> float:
        """How far a settled read-back of ``current_a`` may be from it: the stated accuracy plus
        half the set resolution (what was sent is rounded to it)."""
        return self.readback_accuracy_rel * abs(current_a) + self.readback_accuracy_a + 0.5 * self.resolution_a


def load_supply_file(path=PAPER_SUPPLY_FILE) -> ScpiSupplyConfig:
    """The supply YAML at ``path``; ValueError naming the file, the key and the value."""
    return load_yaml(path, "supply file", _supply_config)


def _supply_config(data: Any) -> ScpiSupplyConfig:
    return typed(ScpiSupplyConfig, data, commands=lambda given: typed(ScpiCommands, given or {}))


class ScpiSupply:
    """The supply behind a PyVISA ``resource`` (anything with ``write``, ``query`` and ``close``)."""

    def __init__(self, resource, config: ScpiSupplyConfig):
        self.resource = resource
        self.config = config
        self.identity = ""
        self.identified = False  # its *IDN? named the file's model: commands may be sent
        self.writes = 0
        self.message_since_s: float | None = None  # when the message under way was sent (time.monotonic())

    def prepare(self) -> str:
        """Clear its status, check its identity against the file's model, select the channel, set
        zero current with the output off, the safety limits and the over-voltage protection from
        the file's caps, then switch the output (and the master output) on; its identity.
        SupplyError when it is another model or refuses any of it."""
        commands = self.config.commands
        self._write(commands.clear_status)
        self.identity = self._query(commands.identify).strip()
        self._check_model()
        self.identified = True
        if commands.select_channel:
            self._write(commands.select_channel.format(self.config.channel))
        self.output(False)
        self.set_current_a(0.0)
        self._write(commands.set_voltage.format(self.config.voltage_limit_v))
        self._protect()
        if commands.clear_protection:
            self._write(commands.clear_protection)  # a trip told before is reset only now, at zero
        self.output(True)
        if commands.master_output:
            self._write(commands.master_output.format(1))
        return self.identity

    def _check_model(self) -> None:
        fields = [field.strip() for field in self.identity.split(",")]
        model = fields[1] if len(fields) > 1 else self.identity
        if model.casefold() != self.config.model.strip().casefold():
            raise SupplyError(
                f"{self.config.name}: the instrument at this address is {self.identity!r}, model {model!r}, "
                f"not the supply file's {self.config.model!r}: nothing else was sent to it"
            )

    def _protect(self) -> None:
        """The instrument's own limits (the NGx's safety limits: a current above the cap is refused
        by the instrument too) and its over-voltage protection, each where the model has it."""
        commands, config = self.config.commands, self.config
        settings = (
            (commands.current_safety_limit, config.limits.cap_a),
            (commands.voltage_safety_limit, config.voltage_limit_v),
            (commands.safety_limits, 1),
            (commands.over_voltage_level, config.over_voltage_v),
            (commands.over_voltage_protection, 1),
        )
        for command, value in settings:
            if command:
                self._write(command.format(value))

    def set_current_a(self, current_a: float) -> None:
        """Set the current (checked against the cap and the polarity, and rounded; ValueError
        before anything is sent); SupplyError if the supply refuses it."""
        value = self.config.limits.check(current_a)
        self._write(self.config.commands.set_current.format(value))

    def read_current_a(self) -> float:
        """The current the supply measures, A; SupplyError for an answer that is not a number."""
        answer = self._query(self.config.commands.measure_current)
        try:
            value = float(answer)
        except ValueError:
            raise SupplyError(f"{self.config.name}: current read back as {answer!r}, not a number") from None
        if not math.isfinite(value):
            raise SupplyError(f"{self.config.name}: current read back as {answer!r}")
        return value

    def output(self, on: bool) -> None:
        self._write(self.config.commands.output.format(int(on)))

    def safe(self) -> list[str]:
        """Current to zero and output off, then every other channel's output and the master
        output off, each tried whatever the others did and read back as off; what failed."""
        commands = self.config.commands
        steps: list[Callable[[], None]] = [lambda: self.set_current_a(0.0), lambda: self.output(False)]
        steps.append(self._read_back_off)
        for channel in range(1, self.config.channels + 1):
            if channel != self.config.channel:
                steps += [functools.partial(self._select, channel), lambda: self.output(False), self._read_back_off]
        if self.config.channels > 1:
            steps.append(lambda: self._select(self.config.channel))
        if commands.master_output:
            steps += [lambda: self._write(commands.master_output.format(0)), self._read_back_master_off]
        problems = []
        for step in steps:
            try:
                step()
            except SupplyError as error:
                problems.append(str(error))
        return problems

    def _select(self, channel: int) -> None:
        if self.config.commands.select_channel:
            self._write(self.config.commands.select_channel.format(channel))

    def tripped(self) -> bool:
        """Whether the over-voltage protection has tripped (False for a model that cannot say)."""
        query = self.config.commands.protection_tripped
        return bool(query) and self._query(query).strip() in ("1", "ON")

    def output_state(self) -> str:
        """The output as the supply reads it back: 'on' or 'off'; '' for a model without the
        query. SupplyError for an answer that is neither."""
        query = self.config.commands.output_state
        if not query:
            return ""
        answer = self._query(query).strip()
        if answer not in OUTPUT_STATES:
            raise SupplyError(f"{self.config.name}: {query} answers {answer!r}, neither on nor off")
        return OUTPUT_STATES[answer]

    def _read_back_off(self) -> None:
        if self.output_state() == "on":
            query = self.config.commands.output_state
            raise SupplyError(f"{self.config.name}: {query} reads back on after the output was switched off")

    def _read_back_master_off(self) -> None:
        query = self.config.commands.master_output_state
        if query and OUTPUT_STATES.get(self._query(query).strip()) != "off":
            raise SupplyError(f"{self.config.name}: {query} does not read back off after the master output was")

    def close(self) -> None:
        """Current to zero at once (the caller has ramped it down) and output off (:meth:`safe`),
        the instrument back to local control, the link released; SupplyError naming every step
        that failed, after all were tried."""
        problems = self.safe()
        try:
            if self.config.commands.local:
                self._write(self.config.commands.local)
        except SupplyError as error:
            problems.append(str(error))
        finally:
            self.resource.close()
        if problems:
            raise SupplyError("; ".join(problems))

    def _write(self, command: str) -> None:
        """Send ``command`` and read the whole error queue; SupplyError naming every entry."""
        self.writes += 1
        self._call(self.resource.write, command)
        errors = self._errors()
        if errors:
            raise SupplyError(f"{self.config.name}: {command!r} refused: {'; '.join(errors)}")

    def _errors(self) -> list[str]:
        """The error queue's entries, oldest first, until it answers that there is none."""
        commands = self.config.commands
        errors: list[str] = []
        for _ in range(MAX_ERRORS):
            entry = self._call(self.resource.query, commands.query_error).strip()
            if entry.startswith(commands.no_error):
                return errors
            errors.append(entry)
        return [*errors, f"more than {MAX_ERRORS} entries, the rest left in the queue"]

    def _query(self, command: str) -> str:
        return self._call(self.resource.query, command)

    def _call(self, method, command: str) -> str:
        """One message: ``method(command)``, the time it was sent kept while it is under way (a
        caller on another thread judges a hung exchange by it)."""
        self.message_since_s = time.monotonic()
        try:
            return method(command)
        except Exception as error:  # PyVISA's errors have no common base outside pyvisa.errors
            raise SupplyError(f"{self.config.name}: {command!r}: {error}") from None
        finally:
            self.message_since_s = None


def open_scpi_supply(resource_name: str, config: ScpiSupplyConfig, visa_library: str = "@py") -> ScpiSupply:
    """The supply at ``resource_name`` through PyVISA (``@py``: the pure-Python pyvisa-py; a path
    to a pyvisa-sim file + ``@sim``: a simulated one, :mod:`mows.device.simulated.visa_supply`),
    prepared (:meth:`ScpiSupply.prepare`). SupplyError, one line, when PyVISA or the supply is
    missing, is another model or refuses its preparation (then, if it is the file's model, at zero
    current with its output off)."""
    try:
        pyvisa = importlib.import_module("pyvisa")
    except ImportError:
        raise SupplyError(
            "supply scpi: the Python package pyvisa is not installed (pip install pyvisa pyvisa-py)"
        ) from None
    try:
        manager = pyvisa.ResourceManager(_library(visa_library))
        resource = manager.open_resource(
            resource_name,
            write_termination=config.write_termination,
            read_termination=config.read_termination,
            timeout=round(config.timeout_s * 1000),
        )
    except Exception as error:  # noqa: BLE001 (PyVISA raises its own, OSError and ValueError here)
        first = (str(error).splitlines() or [type(error).__name__])[0][:200]
        raise SupplyError(f"supply scpi: cannot open {resource_name!r} ({visa_library}): {first}") from None
    supply = ScpiSupply(resource, config)
    try:
        supply.prepare()
    except SupplyError:
        if supply.identified:
            supply.safe()
        resource.close()
        raise
    return supply


def _library(visa_library: str):
    """PyVISA's library for ``visa_library``; a pyvisa-sim file (``…@sim``) under the supply's
    behaviour that pyvisa-sim cannot express (:class:`SimulatedSupplyLibrary`)."""
    if not visa_library.endswith("@sim"):
        return visa_library
    from mows.device.simulated.visa_supply import SimulatedSupplyLibrary  # pyvisa-sim only when simulating

    return SimulatedSupplyLibrary(visa_library.removesuffix("@sim") or "unset")
