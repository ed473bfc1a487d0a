"""NI's interpreter interface (:class:`nidaqmx._base_interpreter.BaseInterpreter`) on the
simulated card (:class:`mows.device.simulated.daqmx_card.SimulatedCard`): the lowest layer of
NI's ``nidaqmx`` package, the one that calls NI's C library, answering as that library does.
Every call the bench makes is checked as the library checks it and refused with NI's error class
and code (:func:`daq_error`); the attributes it reads and sets are NI's ids, as nidaqmx's
generated properties pass them; every call the bench does not make raises
``DaqFunctionNotSupportedError``.
"""

from __future__ import annotations

import abc
import math
from typing import TYPE_CHECKING

import numpy as np
from nidaqmx._base_interpreter import BaseInterpreter
from nidaqmx.constants import ChannelType
from nidaqmx.error_codes import DAQmxErrors
from nidaqmx.errors import DaqError, DaqFunctionNotSupportedError, DaqReadError, DaqWriteError

if TYPE_CHECKING:
    from mows.device.simulated.daqmx_card import SimulatedCard

# The attributes the bench's calls reach (NI's ids, as nidaqmx's generated properties pass them).
TASK_NAME = 0x1276
CHANNEL_TYPE = 0x187F
SAMP_CLK_RATE = 0x1344
SAMP_CLK_TIMEBASE_RATE = 0x1303
AO_IDLE_OUTPUT_BEHAVIOR = 0x2240
REGEN_MODE = 0x1453
READ_NUM_CHANS = 0x217B
WRITE_NUM_CHANS = 0x217E
READ_AVAIL_SAMP_PER_CHAN = 0x1223
READ_TOTAL_SAMP_PER_CHAN_ACQUIRED = 0x192A
WRITE_TOTAL_SAMP_PER_CHAN_GENERATED = 0x192B

_MESSAGES = {
    DAQmxErrors.SAMPLES_NO_LONGER_AVAILABLE: (
        "Attempted to read samples that are no longer available. The requested sample was previously "
        "available, but has since been overwritten."
    ),
    DAQmxErrors.GEN_STOPPED_TO_PREVENT_REGEN_OF_OLD_SAMPLES: (
        "The generation has stopped to prevent the regeneration of old samples. Your application was "
        "unable to write samples to the background buffer fast enough to prevent old samples from "
        "being regenerated."
    ),
    DAQmxErrors.DEV_CANNOT_BE_ACCESSED: (
        "Device cannot be accessed. Possible causes: Device is no longer present in the system."
    ),
    DAQmxErrors.SAMPLES_NOT_YET_AVAILABLE: "Some or all of the samples requested have not yet been acquired.",
}


def daq_error(code: DAQmxErrors, detail: str = "", *, read: bool = False, write: bool = False) -> DaqError:
    """NI's error class for ``code`` as its library interpreter raises it (a read or a write: with
    the samples transferred, none)."""
    message = " ".join(part for part in (_MESSAGES.get(code, ""), detail) if part)
    if read:
        return DaqReadError(message, code.value, 0)
    if write:
        return DaqWriteError(message, code.value, 0)
    return DaqError(message, code.value)


def _locked(method):
    """The card's lock around an interpreter call (the driver's stream and watchdog threads share it)."""

    def call(self, *args):
        with self.card._lock:
            return method(self, *args)

    call.__name__ = method.__name__
    return call


class SimulatedInterpreter(BaseInterpreter):
    """NI's interpreter interface (:class:`nidaqmx._base_interpreter.BaseInterpreter`) on a
    :class:`SimulatedCard`; the calls the bench does not make raise ``DaqFunctionNotSupportedError``."""

    __slots__ = ("card",)

    def __init__(self, card: SimulatedCard):
        self.card = card

    @_locked
    def create_task(self, session_name):
        return self.card.create(session_name), True

    @_locked
    def clear_task(self, task):
        self.card.clear(task)

    def hash_task_handle(self, task_handle):
        return hash(task_handle)

    def internal_get_last_created_chan(self):
        raise DaqFunctionNotSupportedError("internal_get_last_created_chan")

    @_locked
    def create_ai_voltage_chan(
        self, task, physical_channel, name_to_assign_to_channel, terminal_config, min_val, max_val, units, scale
    ):
        self.card.add_channel(task, "ai", physical_channel, min_val, max_val)

    @_locked
    def create_ao_voltage_chan(self, task, physical_channel, name_to_assign_to_channel, min_val, max_val, units, scale):
        self.card.add_channel(task, "ao", physical_channel, min_val, max_val)

    @_locked
    def cfg_samp_clk_timing(self, task, rate, source, active_edge, sample_mode, samps_per_chan):
        self.card.timing(task, rate, sample_mode, samps_per_chan)

    @_locked
    def get_timing_attribute_double(self, task, attribute):
        if attribute == SAMP_CLK_RATE:
            return self.card.task(task).rate_hz
        if attribute == SAMP_CLK_TIMEBASE_RATE:
            return self.card.timebase_hz
        raise DaqFunctionNotSupportedError(f"timing attribute {attribute:#x}")

    @_locked
    def cfg_dig_edge_start_trig(self, task, trigger_source, trigger_edge):
        self.card.task(task).trigger = trigger_source

    @_locked
    def start_task(self, task):
        self.card.start(task)

    @_locked
    def is_task_done(self, task):
        """Whether ``task`` has stopped; the error that stopped it raised, as NI's library does."""
        card_task = self.card.task(task)
        self.card._advance()
        if card_task.error is not None:
            raise card_task.error
        return not card_task.running

    @_locked
    def stop_task(self, task):
        self.card.stop(task)

    @_locked
    def read_analog_f64(self, task, num_samps_per_chan, timeout, fill_mode, read_array):
        card_task = self.card.task(task)
        if not 0.0 < timeout < math.inf:
            raise daq_error(
                DAQmxErrors.INVALID_ATTRIBUTE_VALUE, f"The bench's reads time out: timeout = {timeout!r} s."
            )
        if not 0 < num_samps_per_chan <= card_task.buffer_samples:
            raise daq_error(DAQmxErrors.READ_BUFFER_TOO_SMALL, f"{num_samps_per_chan} samples per channel requested.")
        read_array[:] = self.card.read(card_task, num_samps_per_chan, timeout)
        return read_array, num_samps_per_chan

    @_locked
    def write_analog_f64(self, task, num_samps_per_chan, auto_start, timeout, data_layout, write_array):
        card_task = self.card.task(task)
        if auto_start:
            raise daq_error(DAQmxErrors.INVALID_ATTRIBUTE_VALUE, "A triggered output is started explicitly.")
        ranges = np.array([r for _, r in card_task.channels])[:, None]
        if np.any(np.abs(write_array) > ranges):
            raise daq_error(DAQmxErrors.INVALID_AO_DATA_WRITE, "Value passed to the Task/Channels is out of range.")
        return self.card.write(card_task, np.array(write_array[:, :num_samps_per_chan]))

    @_locked
    def get_task_attribute_string(self, task, attribute):
        if attribute != TASK_NAME:
            raise DaqFunctionNotSupportedError(f"task attribute {attribute:#x}")
        return self.card.task(task).name

    @_locked
    def get_chan_attribute_int32(self, task, channel, attribute):
        if attribute != CHANNEL_TYPE:
            raise DaqFunctionNotSupportedError(f"channel attribute {attribute:#x}")
        kind = self.card.task(task).kind
        return (ChannelType.ANALOG_INPUT if kind == "ai" else ChannelType.ANALOG_OUTPUT).value

    @_locked
    def set_chan_attribute_int32(self, task, channel, attribute, value):
        if attribute != AO_IDLE_OUTPUT_BEHAVIOR:
            raise DaqFunctionNotSupportedError(f"channel attribute {attribute:#x}")
        self.card.task(task).idle_behavior = value

    @_locked
    def set_write_attribute_int32(self, task, attribute, value):
        if attribute != REGEN_MODE:
            raise DaqFunctionNotSupportedError(f"write attribute {attribute:#x}")
        self.card.task(task).regen_mode = value

    @_locked
    def get_write_attribute_int32(self, task, attribute):
        if attribute != REGEN_MODE:
            raise DaqFunctionNotSupportedError(f"write attribute {attribute:#x}")
        return self.card.task(task).regen_mode

    @_locked
    def get_read_attribute_uint32(self, task, attribute):
        card_task = self.card.task(task)
        if attribute == READ_NUM_CHANS:
            return len(card_task.channels)
        if attribute == READ_AVAIL_SAMP_PER_CHAN:
            return max(0, self.card._acquired() - card_task.position) if card_task.running else 0
        raise DaqFunctionNotSupportedError(f"read attribute {attribute:#x}")

    @_locked
    def get_read_attribute_uint64(self, task, attribute):
        if attribute != READ_TOTAL_SAMP_PER_CHAN_ACQUIRED:
            raise DaqFunctionNotSupportedError(f"read attribute {attribute:#x}")
        return self.card._acquired() if self.card.task(task).running else 0

    @_locked
    def get_write_attribute_uint32(self, task, attribute):
        if attribute != WRITE_NUM_CHANS:
            raise DaqFunctionNotSupportedError(f"write attribute {attribute:#x}")
        return len(self.card.task(task).channels)

    @_locked
    def get_write_attribute_uint64(self, task, attribute):
        if attribute != WRITE_TOTAL_SAMP_PER_CHAN_GENERATED:
            raise DaqFunctionNotSupportedError(f"write attribute {attribute:#x}")
        card_task = self.card.task(task)
        self.card._advance()
        return min(self.card._acquired(), card_task.position) if card_task.running else 0


def _unsupported(name: str):
    def call(self, *args, **kwargs):
        raise DaqFunctionNotSupportedError(f"{name} is not simulated: the bench does not call it")

    call.__name__ = name
    return call


for _name in BaseInterpreter.__abstractmethods__ - vars(SimulatedInterpreter).keys():
    setattr(SimulatedInterpreter, _name, _unsupported(_name))
abc.update_abstractmethods(SimulatedInterpreter)
