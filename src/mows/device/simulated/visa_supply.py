"""The field supply simulated under PyVISA: pyvisa-sim's instrument (the NGM202's commands,
``mows/device/instruments/hardware/ngm202_pyvisa_sim.yaml``) with what a pyvisa-sim file cannot
express, added at PyVISA's lowest layer (the library behind :class:`pyvisa.ResourceManager`), so
that :class:`mows.device.instruments.scpi.ScpiSupply` meets it through PyVISA as it meets the
real one:

- every exchange takes ``latency_s`` (a supply on the LAN answers in milliseconds, not at once);
- ``*CLS`` empties the error queue (pyvisa-sim queues an entry for a command it does not know or
  a value outside a property's range, but has no command that clears them);
- a value outside a property's range is ``-222,"Data out of range"``, as the NGM202 says, not
  pyvisa-sim's ``-100``;
- the current it delivers is 0 A while the channel's or the master output is off, and follows a
  new setting with the time constant ``SETTLE_TAU_S`` (the pair's inductance);
- ``MEAS:CURR?`` reads the delivered current with Gaussian noise of ``READBACK_NOISE_A``, not the
  setting;
- a second channel (``INST:NSEL 2``) whose output can be switched and read back;
- faults on demand: :meth:`SupplyInstrument.lose` (the next messages are lost, so a query times
  out after the resource's VISA timeout, ``VI_ERROR_TMO``, as over a dropped LAN link) and
  :meth:`SupplyInstrument.trip_over_voltage` (the output goes off by itself, ``VOLT:PROT:TRIP?``
  answers 1 and ``OUTP 1`` is refused, ``-221``, until ``VOLT:PROT:CLE``).

Only the pyvisa-sim devices with ``current`` and ``output`` properties get this behaviour; the
master output is the ``general`` property where the file has one.
"""

from __future__ import annotations

import math
import re
import threading
import time

import numpy as np
from pyvisa_sim.component import NoResponse
from pyvisa_sim.highlevel import SimVisaLibrary

LATENCY_S = 0.002  # each exchange
SETTLE_TAU_S = 0.01  # the delivered current's time constant after a step
READBACK_NOISE_A = 2.0e-4  # σ of a read-back, within the NGM202 file's stated accuracy
CHANNELS = 2  # the NGM202's outputs; the file's properties are channel 1's
MEASURE_CURRENT = "MEAS:CURR?"
CLEAR_STATUS = "*CLS"
CHANNEL_COMMANDS = {"OUTP", "OUTP?", "CURR", "CURR?", "VOLT", "VOLT?", "MEAS:CURR?", "CURR:ALIM", "VOLT:ALIM", "ALIM"}
OUT_OF_RANGE = b'-222,"Data out of range"'
SETTINGS_CONFLICT = b'-221,"Settings conflict"'


class SupplyInstrument:
    """One pyvisa-sim device as a supply: its queries answered as the module says, the rest by
    pyvisa-sim. ``rng`` draws the read-back's noise."""

    def __init__(self, device, rng: np.random.Generator):
        self._device = device
        self._answer = device._match  # pyvisa-sim's own matching
        self._rng = rng
        self._from_a = self._to_a = 0.0
        self._since_s = time.monotonic()
        self.latency_s = LATENCY_S
        self.selected = 1
        self.other_outputs = dict.fromkeys(range(2, CHANNELS + 1), 0)  # channel → output state
        self.tripped = False
        self.exchanges = 0
        self._lost = 0
        self._lock = threading.Lock()
        device._match = self.match

    def lose(self, messages: int) -> None:
        """The next ``messages`` messages are lost: not applied, never answered."""
        with self._lock:
            self._lost = messages

    def trip_over_voltage(self) -> None:
        """The over-voltage protection trips: the channel's output goes off by itself."""
        with self._lock:
            self.tripped = True
            self._device._properties["output"].set_value(0)
            self.delivered_a()

    def match(self, query: bytes):
        """The answer to ``query`` (None: pyvisa-sim queues a command error)."""
        time.sleep(self.latency_s)
        with self._lock:
            self.exchanges += 1
            if self._lost:
                self._lost -= 1
                return NoResponse
            answer = self._match(query.decode("utf-8").strip(), query)
            self.delivered_a()  # a new setting is followed from now
            return answer

    def _match(self, text: str, query: bytes):
        if text == CLEAR_STATUS:
            for queue in self._device._error_queues.values():
                queue.clear()
            return NoResponse
        if text == MEASURE_CURRENT:
            return f"{self.delivered_a() + self._rng.normal(0.0, READBACK_NOISE_A):.5f}".encode()
        if text == "VOLT:PROT:TRIP?":
            return b"1" if self.tripped else b"0"
        if text == "VOLT:PROT:CLE":
            self.tripped = False
            return NoResponse
        if select := re.fullmatch(r"INST:NSEL (\d+)", text):
            if not 1 <= int(select.group(1)) <= CHANNELS:
                return self._error(OUT_OF_RANGE)
            self.selected = int(select.group(1))
            return NoResponse
        if self.selected != 1 and text.split(" ")[0] in CHANNEL_COMMANDS:  # the other channels: their outputs only
            return self._other_channel(text)
        if self.tripped and text == "OUTP 1":
            return self._error(SETTINGS_CONFLICT)
        answer = self._answer(query)
        if answer is None and any(_parses(parser, text) for _, parser, _, _ in self._device._setters):
            return self._error(OUT_OF_RANGE)  # a known setting, its value outside the range
        return answer

    def _other_channel(self, text: str):
        if text == "OUTP?":
            return str(self.other_outputs[self.selected]).encode()
        if state := re.fullmatch(r"OUTP ([01])", text):
            self.other_outputs[self.selected] = int(state.group(1))
            return NoResponse
        return None

    def _error(self, entry: bytes):
        for queue in self._device._error_queues.values():
            queue._queue.append(entry)
        return NoResponse

    def setting_a(self) -> float:
        """The current the outputs let through: the setting, or 0 A with an output off."""
        properties = self._device._properties
        on = properties["output"].get_value() and ("general" not in properties or properties["general"].get_value())
        return float(properties["current"].get_value()) if on else 0.0

    def delivered_a(self) -> float:
        """The current in the pair now: first order towards :meth:`setting_a` since it changed."""
        now = time.monotonic()
        value = self._to_a + (self._from_a - self._to_a) * math.exp(-(now - self._since_s) / SETTLE_TAU_S)
        target = self.setting_a()
        if target != self._to_a:
            self._from_a, self._to_a, self._since_s = value, target, now
        return value


def _parses(parser, text: str) -> bool:
    try:
        parser(text)
    except ValueError:
        return False
    return True


class SimulatedSupplyLibrary(SimVisaLibrary):
    """pyvisa-sim's library with its supplies as :class:`SupplyInstrument` (``instruments``, by
    resource name); the read-back's noise seeded, so a run is one draw."""

    def _init(self) -> None:
        super()._init()
        rng = np.random.default_rng(0)
        self.instruments = {
            name: SupplyInstrument(self.devices[name], rng)
            for name in self.devices.list_resources()
            if {"current", "output"} <= set(self.devices[name]._properties)
        }
