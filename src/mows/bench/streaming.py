"""Streaming benchmark: the share of one CPU core the driver uses to stream 20 kS/s × 2 channels
from the simulator (the goal: below 10 %).

Timed in the same run, each as CPU seconds per second of stream, with the simulator read in
pieces of one 25 ms block (what the driver does):

* ``baseline_generation``: the simulator alone, producing the same samples paced in real time
  (a read, then sleep until the next is due): the cost of the samples themselves;
* ``session``: the sim backend with the block assembler and the cycle sequencer (no cycle
  running), in this process, over ``duration_s`` of wall time;
* ``node``: the driver node process (backend sim, publishing on /mows/raw), its own CPU time
  (/proc/<pid>/stat, all threads) over ``duration_s`` after a warm-up, when the ROS workspace
  is built and sourced; None, with the reason, when it is not.

* ``nidaqmx_catch_up``: the NI backend on the simulated card (NI's ``nidaqmx`` above it), its
  host held ``BEHIND_S`` behind the card's wall clock, then reading until it has caught up: CPU
  seconds per second of stream read, in reads of up to ``CATCH_UP_BLOCKS`` blocks and, in the
  same run, block by block (``nidaqmx_catch_up_block_by_block``). Their ratio is what the larger
  reads save a host that a loaded machine has put behind.

``*_overhead`` is a figure minus the baseline: what streaming adds to making the samples.
Reads woken from sleep cost about twice what back-to-back reads do (cold caches), which is
why the baseline is paced like the stream.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import time
from pathlib import Path

from mows.device.backends.daqmx_backend import CATCH_UP_BLOCKS, open_daqmx
from mows.device.backends.sim_backend import SimBackend
from mows.device.cycle.phases import CycleSettings
from mows.device.instruments.daq import load_daq_device
from mows.device.simulated.daqmx_card import SimulatedCard
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

GOAL_SHARE = 0.10
BLOCK_S = 0.025  # the driver's default block, and the piece in which it reads the simulator
NODE_WARM_UP_S = 5.0  # imports, the simulator's compiled kernel, the first blocks
CLOCK_TICKS_PER_S = os.sysconf("SC_CLK_TCK")
BEHIND_S = 1.5  # how far the NI backend's host is held behind its card, within the output lead


def _cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def baseline_share(duration_s: float) -> float:
    """CPU seconds per second of samples to simulate them in real time, block by block."""
    device = SimulatedDevice(load_scenario())
    chunk = round(BLOCK_S * device.sample_rate_hz)
    device.read(chunk)  # the compiled kernel's first call is not streaming
    start_cpu, start_wall = _cpu_s(), time.monotonic()
    for k in range(1, round(duration_s / BLOCK_S) + 1):
        device.read(chunk)
        time.sleep(max(0.0, start_wall + k * BLOCK_S - time.monotonic()))
    return (_cpu_s() - start_cpu) / (time.monotonic() - start_wall)


def session_share(duration_s: float) -> tuple[float, int]:
    """CPU share of the paced sim backend and session in this process; and the blocks made."""
    scenario = load_scenario()
    backend = SimBackend(SimulatedDevice(scenario), CurrentCap(), chunk_s=BLOCK_S)
    session = DeviceSession(
        backend, SessionConfig(BLOCK_S, CycleSettings(), scenario.setup, CurrentCap(), 112.5, fit_tuning)
    )
    session.step(1.0)  # the compiled kernel's first call
    blocks = 0
    start_cpu, start_wall = _cpu_s(), time.monotonic()
    while time.monotonic() - start_wall < duration_s:
        blocks += len(session.step(0.02).blocks)
    share = (_cpu_s() - start_cpu) / (time.monotonic() - start_wall)
    session.close()
    return share, blocks


def catch_up_share(catch_up_blocks: int) -> float:
    """CPU seconds per second of stream that the NI backend, ``BEHIND_S`` behind its simulated
    card, spends catching up in reads of up to ``catch_up_blocks`` blocks."""
    card = SimulatedCard(SimulatedDevice(load_scenario()))
    with card.installed():
        backend = open_daqmx(load_daq_device(), CurrentCap())
        backend.catch_up_blocks = catch_up_blocks
        try:
            backend.poll(0.05)  # the compiled kernel's first call
            time.sleep(BEHIND_S)
            start_cpu, start_index = _cpu_s(), backend.next_index
            while backend.next_index - start_index < BEHIND_S * backend.device.sample_rate_hz:
                backend.poll(0.05)
            return (_cpu_s() - start_cpu) * backend.device.sample_rate_hz / (backend.next_index - start_index)
        finally:
            backend.close()


def driver_executable() -> Path | None:
    """The driver's console script in the sourced workspace (AMENT_PREFIX_PATH), if any."""
    for prefix in filter(None, os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep)):
        candidate = Path(prefix) / "lib" / "mows_driver" / "mows_driver"
        if candidate.is_file():
            return candidate
    return None


def _process_cpu_s(pid: int) -> float:
    # /proc/<pid>/stat: the fields after the command's closing parenthesis; utime, stime are 14, 15.
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLOCK_TICKS_PER_S


def node_share(duration_s: float) -> tuple[float | None, str]:
    """CPU share of the driver node process streaming from the simulator, and a note."""
    executable = driver_executable()
    if executable is None:
        return None, "the ROS workspace is not sourced (no mows_driver under AMENT_PREFIX_PATH)"
    environment = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", **os.environ}
    # A namespace of its own: its blocks must not reach a graph running beside the benchmark.
    namespace = f"/mows_benchmark_{os.getpid()}"
    command = [str(executable), "--ros-args", "-r", f"__ns:={namespace}"]
    process = subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL, env=environment
    )
    try:
        time.sleep(NODE_WARM_UP_S)
        if process.poll() is not None:
            return None, f"the driver exited with code {process.returncode} during warm-up"
        start_cpu, start_wall = _process_cpu_s(process.pid), time.monotonic()
        time.sleep(duration_s)
        share = (_process_cpu_s(process.pid) - start_cpu) / (time.monotonic() - start_wall)
    finally:
        process.send_signal(signal.SIGTERM)
        process.wait()
    return share, f"driver node process {process.pid} in {namespace}, backend sim, no subscriber"


def run(duration_s: float = 10.0) -> dict:
    """The figures of the module docstring, as shares of one core (1.0 = a whole core)."""
    baseline = baseline_share(duration_s)
    session, blocks = session_share(duration_s)
    node, note = node_share(duration_s)
    catch_up, block_by_block = catch_up_share(CATCH_UP_BLOCKS), catch_up_share(1)
    return {
        "duration_s": duration_s,
        "stream": "20 kS/s x 2 channels, 25 ms blocks",
        "baseline_generation_share": baseline,
        "session_share": session,
        "session_overhead_share": session - baseline,
        "session_blocks": blocks,
        "node_share": node,
        "node_overhead_share": None if node is None else node - baseline,
        "node_note": note,
        "goal_share": GOAL_SHARE,
        "meets_goal": None if node is None else node < GOAL_SHARE,
        "nidaqmx_behind_s": BEHIND_S,
        "nidaqmx_catch_up_cpu_s_per_s": catch_up,
        "nidaqmx_catch_up_block_by_block_cpu_s_per_s": block_by_block,
        "nidaqmx_catch_up_over_block_by_block": catch_up / block_by_block,
    }
