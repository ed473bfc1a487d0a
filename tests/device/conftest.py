"""Fixtures of the device tests."""

import contextlib
import dataclasses

import pytest

from mows.device.backends.daqmx_backend import open_daqmx
from mows.device.instruments.daq import load_daq_device
from mows.device.simulated.daqmx_card import SimulatedCard
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

# The tests fit tuning ring-downs between reads on a busy machine: the watchdog is for a host that hung.
WATCHDOG_S = 30.0


@pytest.fixture
def installed(record_property):
    """Installs a simulated card (:class:`mows.device.simulated.daqmx_card.SimulatedCard`: NI's
    ``nidaqmx`` drives it) until the test ends; gives back the card. The longest the host left
    the card's outputs unfed goes to the test's report (``--junitxml``: the stalls a loaded
    machine gives, beside the output lead)."""
    cards: list[SimulatedCard] = []

    def install(card: SimulatedCard) -> SimulatedCard:
        cards.append(card)
        return stack.enter_context(card.installed())

    with contextlib.ExitStack() as stack:
        yield install
    if cards:
        record_property("longest_write_gap_s", round(max(c.longest_write_gap_s for c in cards), 3))
        record_property("underflows", sum(c.underflows for c in cards))


@pytest.fixture
def on_bench(installed):
    """The backend on a simulated card of ``scenario`` (with ``supply`` on it), and the card;
    ``watchdog_s`` None: the paper's device file's own."""

    made = []

    def make(scenario="paper_largest_spacing", supply=None, watchdog_s=WATCHDOG_S):
        card = installed(SimulatedCard(SimulatedDevice(load_scenario(scenario))))
        if supply is not None:
            card.supply_current_a = lambda: _supply_state(supply)[0] * _supply_state(supply)[1]
        device = load_daq_device()
        device = device if watchdog_s is None else dataclasses.replace(device, watchdog_s=watchdog_s)
        made.append(open_daqmx(device, CurrentCap(10.0), supply))
        return card, made[-1]

    yield make
    for backend in made:  # a failed test's bench closed, not left to switch the next test's supply off
        backend.close()


def _supply_state(supply) -> tuple[float, int]:
    """The pyvisa-sim instrument's own current and output state (not through the backend)."""
    properties = supply.resource.visalib.devices[supply.resource.resource_name]._properties
    return properties["current"].get_value(), properties["output"].get_value()
