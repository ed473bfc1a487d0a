"""Latency in the node graph, from the last sample of a ring-down to its published fit.

It needs ROS, which this library never imports: the measurement is ``mows-latency`` of the
mows_bringup package (the driver on the simulated device and the estimator, as processes),
run here as a subprocess in the sourced workspace (``source install/setup.bash``).
"""

import json
import shutil
import subprocess


def run(cycles: int = 4, repeats: int = 5, tracking: bool = False) -> dict:
    """``mows-latency``'s figures; ``tracking``: of the driver's tracking mode (cycles × repeats ring-downs)."""
    tool = shutil.which("mows-latency")
    if tool is None:
        return {"skipped": "mows-latency not on PATH: source install/setup.bash (make bench does)"}
    done = subprocess.run(
        [tool, "--json", "--cycles", str(cycles), "--repeats", str(repeats), *(["--tracking"] if tracking else [])],
        capture_output=True,
        text=True,
        timeout=600,
    )
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        return {"failed": (done.stderr or done.stdout)[-500:]}
    return json.loads(lines[-1])
