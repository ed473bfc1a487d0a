"""The field supply simulated under PyVISA: pyvisa-sim's instrument (the NGM202's commands,
``mows/device/instruments/hardware/ngm202_pyvisa_sim.yaml``) with what a pyvisa-sim file cannot
express, added at PyVISA's lowest layer (the library behind :class:`pyvisa.ResourceManager`), so
that :class:`mows.device.instruments.scpi.ScpiSupply` meets it through PyVISA as it meets the
real one:

- every exchange takes ``LATENCY_S`` (a supply on the LAN answers in milliseconds, not at once);
- ``*CLS`` empties the error queue (pyvisa-sim queues an entry for a command it does not know or
  a value outside a property's range, but has no command that clears them);
- the current it delivers is 0 A while the channel's or the master output is off, and follows a
  new setting with the time constant ``SETTLE_TAU_S`` (the pair's inductance);
- ``MEAS:CURR?`` reads the delivered current with Gaussian noise of ``READBACK_NOISE_A``, not the
  setting.

Only the pyvisa-sim devices with ``current`` and ``output`` properties get this behaviour; the
master output is the ``general`` property where the file has one.
"""

from __future__ import annotations

import math
import time

import numpy as np
from pyvisa_sim.component import NoResponse
from pyvisa_sim.highlevel import SimVisaLibrary

LATENCY_S = 0.002  # each exchange
SETTLE_TAU_S = 0.01  # the delivered current's time constant after a step
READBACK_NOISE_A = 2.0e-4  # σ of a read-back, within the NGM202 file's stated accuracy
MEASURE_CURRENT = "MEAS:CURR?"
CLEAR_STATUS = "*CLS"


class SupplyInstrument:
    """One pyvisa-sim device as a supply: its queries answered as the module says, the rest by
    pyvisa-sim. ``rng`` draws the read-back's noise."""

    def __init__(self, device, rng: np.random.Generator):
        self._device = device
        self._answer = device._match  # pyvisa-sim's own matching
        self._rng = rng
        self._from_a = self._to_a = 0.0
        self._since_s = time.monotonic()
        device._match = self.match

    def match(self, query: bytes):
        """The answer to ``query`` (None: pyvisa-sim queues a command error)."""
        time.sleep(LATENCY_S)
        text = query.decode("utf-8").strip()
        if text == CLEAR_STATUS:
            for queue in self._device._error_queues.values():
                queue.clear()
            return NoResponse
        if text == MEASURE_CURRENT:
            return f"{self.delivered_a() + self._rng.normal(0.0, READBACK_NOISE_A):.5f}".encode()
        answer = self._answer(query)
        self.delivered_a()  # a new setting is followed from now
        return answer

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
