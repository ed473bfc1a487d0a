"""The NI card's two tasks as the bench needs them, through NI's ``nidaqmx``: the package
imported when a backend is made, in one line when it is missing (:class:`DeviceUnavailable`);
the fluxgates' inputs and the coils' outputs configured on one sample clock, the rate the card
will really run at read back and a rate its timebase does not divide refused, not coerced
(:func:`configure_tasks`); every task closed whatever the others do (:func:`close_tasks`).
"""

from __future__ import annotations

import importlib
import math

import numpy as np

from mows.device.instruments.daq import DaqDevice

INPUT_BUFFER_S = 10.0  # the card's input buffer: a host late by less than this loses nothing
TASK_NAMES = ("mows_fluxgates", "mows_coils")  # named: a second driver on the card is refused


class DeviceUnavailable(OSError):
    """NI's runtime, the ``nidaqmx`` package or the card is missing, or the card refused the tasks."""


def import_nidaqmx():
    """NI's ``nidaqmx`` package with its stream readers and writers (``import nidaqmx`` loads
    neither); DeviceUnavailable, one line, when it is not installed."""
    try:
        nidaqmx = importlib.import_module("nidaqmx")
        importlib.import_module("nidaqmx.stream_readers")
        importlib.import_module("nidaqmx.stream_writers")
    except ImportError:
        raise DeviceUnavailable(
            "backend nidaqmx: the Python package nidaqmx is not installed (pip install nidaqmx==1.7.0)"
        ) from None
    return nidaqmx


def first_line(error: Exception) -> str:
    """An error's first line, with NI's error code."""
    line = (str(error).strip().splitlines() or [type(error).__name__])[0]
    code = getattr(error, "error_code", None)
    return f"{line} ({code})" if code is not None and str(code) not in line else line


def input_buffer_samples(device: DaqDevice) -> int:
    """The inputs' buffer on the card, samples per channel."""
    return round(INPUT_BUFFER_S * device.sample_rate_hz)


def configure_tasks(daqmx, device: DaqDevice, ai, ao) -> None:
    """Channels, timing (the rate read back: :func:`check_rate`), the outputs' trigger on the
    inputs' start, regeneration off and 0 V when idle, as the bench needs them."""
    constants = daqmx.constants
    for channel in device.inputs:
        ai.ai_channels.add_ai_voltage_chan(
            channel.physical_channel,
            terminal_config=constants.TerminalConfiguration[channel.terminal_config],
            min_val=-channel.range_v,
            max_val=channel.range_v,
        )
    ai.timing.cfg_samp_clk_timing(
        device.sample_rate_hz,
        sample_mode=constants.AcquisitionType.CONTINUOUS,
        samps_per_chan=input_buffer_samples(device),
    )
    check_rate(device, ai)
    for output in device.outputs:
        ao.ao_channels.add_ao_voltage_chan(output.physical_channel, min_val=-output.range_v, max_val=output.range_v)
    # When the host stops writing the card underflows and stops: the coils go to zero, not stay on.
    ao.ao_channels.all.ao_idle_output_behavior = constants.AOIdleOutputBehavior.ZERO_VOLTS
    ao.timing.cfg_samp_clk_timing(
        device.sample_rate_hz,
        sample_mode=constants.AcquisitionType.CONTINUOUS,
        samps_per_chan=2 * (device.lead_samples + device.block_samples),
    )
    check_rate(device, ao)
    ao.triggers.start_trigger.cfg_dig_edge_start_trig(device.start_trigger)
    ao.out_stream.regen_mode = constants.RegenerationMode.DONT_ALLOW_REGENERATION


def check_rate(device: DaqDevice, task) -> None:
    """The rate the card runs ``task`` at, read back: a card coerces a rate its timebase does
    not divide to one it does (30 kS/s on 100 MHz is 30 003 S/s, a 100 ppm bias on every
    frequency), which the stamps and fits would not know; DeviceUnavailable, one line."""
    actual_hz, wanted_hz = task.timing.samp_clk_rate, device.sample_rate_hz
    if not math.isclose(actual_hz, wanted_hz, rel_tol=1e-12):
        timebase_hz = task.timing.samp_clk_timebase_rate
        raise DeviceUnavailable(
            f"backend nidaqmx: card {device.device_name!r} samples at {actual_hz:.6f} S/s, not "
            f"sample_rate_hz = {wanted_hz:g}: its {timebase_hz / 1e6:g} MHz timebase does not divide it; "
            f"give a rate it divides (e.g. {timebase_hz / math.ceil(timebase_hz / wanted_hz):.6g})"
        )


def close_tasks(daqmx, tasks: list) -> list[str]:
    """Close every task, whatever the others do (a card that went away refuses); what failed."""
    problems = []
    for task in tasks:
        try:
            task.close()
        except daqmx.errors.DaqError as error:
            problems.append(first_line(error))
    return problems


def read_waiting(ai, reader, device: DaqDevice, buffer: np.ndarray, most_blocks: int) -> np.ndarray:
    """The next block of the input task ``ai`` (into ``buffer``), or the blocks waiting on the
    card, up to ``most_blocks``: a host behind its card catches up in larger reads, each cheaper
    per sample than a block's."""
    n = device.block_samples
    waiting = min(ai.in_stream.avail_samp_per_chan, input_buffer_samples(device))
    count = min(max(1, waiting // n), most_blocks)
    volts = buffer if count == 1 else np.zeros((buffer.shape[0], count * n))
    reader.read_many_sample(volts, number_of_samples_per_channel=count * n, timeout=device.read_timeout_s)
    return volts
