"""Fixtures of the device tests."""

import contextlib

import pytest


@pytest.fixture
def installed():
    """Installs a simulated card (:class:`mows.device.simulated.daqmx_card.SimulatedCard`: NI's
    ``nidaqmx`` drives it) until the test ends; gives back the card."""
    with contextlib.ExitStack() as stack:
        yield lambda card: stack.enter_context(card.installed())
