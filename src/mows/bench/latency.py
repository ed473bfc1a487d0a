"""Latency in the node graph, from the last sample of a ring-down to its published fit.

It needs ROS, which this library never imports: the measurement is ``mows-latency`` of the
mows_bringup package (the driver on the simulated device and the estimator, as processes),
run here as a subprocess in the sourced workspace (``source install/setup.bash``). With
``load`` it is ``mows-latency --load``: a ``load_duration_s`` stream of cycles beside two CPU
burners and a 1 kHz JointState loop, with the gaps counted and the load as run reported, and
the same stream without the load as the baseline. Under load the driver and the estimator run
under SCHED_FIFO (``--realtime-priority``, as a robot computer would run them); the same loaded
stream at the default priority is reported beside it (``default_priority``). Both give
``startup_s``, the processes' start to both active (numba's cache as ``make build`` leaves it).
With ``three_probe_map`` the three-probe demo (``mows-demo --scenario three_probes``) runs too,
for ``three_probe_map_s``: from the last ring-down's fit to the field map of the three probes,
the median of ``three_probe_runs`` demos (each one's in ``three_probe_map_runs_s``); with
``load`` beside the same ``burners`` (``three_probe_map_load``: the load average at the start
and end of each demo).
"""

import contextlib
import json
import multiprocessing
import os
import re
import shutil
import statistics
import subprocess
import tempfile

# SCHED_FIFO priority of the ring-down path under load: above everything best-effort, below a
# robot's own control loop (commonly 80–98 on a PREEMPT_RT computer).
REALTIME_PRIORITY = 40
BURNERS = 2  # mows-latency --load's default


def run(
    cycles: int = 4,
    repeats: int = 5,
    tracking: bool = False,
    load: bool = False,
    load_duration_s: float = 60.0,
    burner_nice: int = 0,
    realtime_priority: int = REALTIME_PRIORITY,
    three_probe_map: bool = True,
    burners: int = BURNERS,
    three_probe_runs: int = 1,
) -> dict:
    """``mows-latency``'s figures; ``tracking``: of the driver's tracking mode (cycles × repeats
    ring-downs); ``load``: under load, with as ``baseline`` the same stream without the load, run
    just before (the machine is shared: its own load is in both); ``burner_nice``: the burners'
    niceness (19 in a quick smoke run, so that it does not starve the tests beside it);
    ``realtime_priority``: the ring-down path's SCHED_FIFO priority under load (0: the default
    policy, and no second loaded stream); ``burners``: how many CPU burners make the load;
    ``three_probe_runs``: how many three-probe demos (one after the other) the map's delay is
    the median of."""
    tool = shutil.which("mows-latency")
    if tool is None:
        return {"skipped": "mows-latency not on PATH: source install/setup.bash (make bench does)"}
    if not load:
        figures = _measure(tool, repeats, ["--cycles", str(cycles), *(["--tracking"] if tracking else [])])
        return {**figures, **_three_probe_maps(three_probe_runs)} if three_probe_map and not tracking else figures
    baseline = _measure(tool, repeats, ["--duration", str(load_duration_s)])
    loaded = ["--load", "--duration", str(load_duration_s), "--burner-nice", str(burner_nice)]
    loaded += ["--burners", str(burners)]
    figures = {
        **_measure(tool, repeats, [*loaded, "--realtime-priority", str(realtime_priority)]),
        "baseline": baseline,
    }
    if realtime_priority:
        figures["default_priority"] = _measure(tool, repeats, loaded)
    if three_probe_map:
        with _burning(burners, burner_nice):
            figures |= _three_probe_maps(three_probe_runs, loaded=True)
    return figures


def _three_probe_maps(runs: int, loaded: bool = False) -> dict:
    """``runs`` three-probe demos: the median delay (``three_probe_map_s``), each run's, and with
    ``loaded`` the 1-minute load average at each run's start and end."""
    delays, loads = [], []
    for _ in range(runs):
        start = os.getloadavg()[0]
        figures = _three_probe_map()
        if "three_probe_map_s" not in figures:
            return figures  # the demo failed: its reason
        delays.append(figures["three_probe_map_s"])
        loads.append((start, os.getloadavg()[0]))
    figures = {"three_probe_map_s": statistics.median(delays), "three_probe_map_runs_s": delays}
    if loaded:
        figures["three_probe_map_load"] = {
            "load_average_1min_start": [start for start, _ in loads],
            "load_average_1min_end": [end for _, end in loads],
        }
    return figures


def _burn(stop, nice: int) -> None:
    """Spin until told to stop: one core's worth of load, at niceness ``nice``."""
    os.nice(nice)
    while not stop.is_set():
        for _ in range(100_000):
            pass


@contextlib.contextmanager
def _burning(count: int, nice: int):
    """``count`` spinning processes while the block runs."""
    context = multiprocessing.get_context("spawn")
    stop = context.Event()
    burners = [context.Process(target=_burn, args=(stop, nice), daemon=True) for _ in range(count)]
    for burner in burners:
        burner.start()
    try:
        yield
    finally:
        stop.set()
        for burner in burners:
            burner.join()


def _measure(tool: str, repeats: int, how: list[str]) -> dict:
    done = subprocess.run(
        [tool, "--json", "--repeats", str(repeats), *how],
        capture_output=True,
        text=True,
        timeout=900,
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        return {"failed": (done.stderr or done.stdout)[-500:]}
    return json.loads(lines[-1])


def _three_probe_map() -> dict:
    """The three-probe demo's delay from the last fit to the field map, and its wall time."""
    demo = shutil.which("mows-demo")
    if demo is None:
        return {"three_probe_map": "mows-demo not on PATH: source install/setup.bash (make bench does)"}
    with tempfile.TemporaryDirectory() as out:
        command = [
            demo,
            "--scenario",
            "three_probes",
            "--angles",
            "8",
            "--repeats",
            "2",
            "--gap-s",
            "0.2",
            "--out",
            out,
        ]
        done = subprocess.run(command, capture_output=True, text=True, timeout=1800)
    found = re.search(r"the field map came (\d+\.\d+) s after the last ring-down's fit", done.stdout)
    if done.returncode != 0 or found is None:
        return {"three_probe_map": f"failed: {(done.stderr or done.stdout)[-300:]}"}
    return {"three_probe_map_s": float(found.group(1))}
