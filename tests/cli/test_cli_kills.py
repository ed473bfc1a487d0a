"""Signals always win: SIGTERM or SIGINT at any moment ends a command with one line and 143 or 130.

Requirement: whenever the signal comes, from the moment the command can catch it to its exit
(the interpreter's own start, before any of the command's code runs, is the operating system's
default: the process dies by the signal, which a shell reports as 143 or 130 too), the command
exits 143 (SIGTERM) or 130 (SIGINT), says so in exactly one line on stderr, and leaves its
output either absent or whole (the bytes of an uninterrupted run), never half-written, and no
temporary or journal behind. The moments are random and cover the whole run: its imports, its
work, its writing and its exit.

KILL_RUNS random moments per command run in the suite (the environment variable
MOWS_KILL_RUNS sets another count: 100 for the full check).
"""

import os
import pathlib
import random
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

HERE = pathlib.Path(__file__).parents[1]
SWEEP_TABLE = HERE / "lab" / "data" / "demo_sweep.csv"
KILL_RUNS = int(os.environ.get("MOWS_KILL_RUNS", "2"))
COMMANDS = {
    "lab-report": (["lab", "report", str(SWEEP_TABLE), "--no-cv", "-o"], "r.html"),
    "sim": (["sim", "--repeats", "2", "--seed", "3", "--out"], "x.npz"),
}
LINES = {signal.SIGTERM: 143, signal.SIGINT: 130}
WORDS = {signal.SIGTERM: "terminated", signal.SIGINT: "interrupted"}


def start(argv: list[str], cwd: pathlib.Path) -> subprocess.Popen:
    # SIGINT as from a terminal: a suite run as a shell's background job inherits it ignored
    command = ["env", "--default-signal=INT", sys.executable, "-m", "mows.cli.main", *argv]
    return subprocess.Popen(command, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def catching(process: subprocess.Popen) -> bool:
    """Whether the command has its own SIGTERM handler in place (Linux's SigCgt mask)."""
    try:
        status = pathlib.Path(f"/proc/{process.pid}/status").read_text()
    except OSError:
        return False
    mask = int(next(line.split()[1] for line in status.splitlines() if line.startswith("SigCgt:")), 16)
    return bool(mask >> (signal.SIGTERM - 1) & 1)


def same_output(path: pathlib.Path, reference: pathlib.Path) -> bool:
    if path.suffix == ".npz":
        with np.load(path) as got, np.load(reference) as want:
            return sorted(got) == sorted(want) and all(np.array_equal(got[k], want[k], equal_nan=True) for k in want)
    return path.read_bytes() == reference.read_bytes()


@pytest.mark.slow  # fresh interpreters loading the lab and the simulator: ~1 min on a loaded machine
@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_a_signal_at_a_random_moment_ends_the_command_with_one_line(tmp_path, name):
    argv, output = COMMANDS[name]
    reference = tmp_path / "reference"
    reference.mkdir()
    began = time.monotonic()
    whole = start([*argv, output], reference)
    assert whole.wait(timeout=600) == 0, whole.stderr.read()
    duration = time.monotonic() - began
    rng = random.Random(f"{name}-{KILL_RUNS}")
    outcomes = []
    for run in range(KILL_RUNS):
        folder = tmp_path / f"run{run}"
        folder.mkdir()
        signum = rng.choice(list(LINES))
        process = start([*argv, output], folder)
        while not catching(process) and process.poll() is None:
            time.sleep(0.005)
        time.sleep(rng.uniform(0.0, 1.1 * duration))
        if process.poll() is not None:  # done before the moment came: nothing to interrupt
            outcomes.append("finished first")
            continue
        process.send_signal(signum)
        err = process.stderr.read()
        status = process.wait(timeout=600)
        assert (status, err) == (LINES[signum], f"mows {name.replace('-', ' ')}: {WORDS[signum]}\n"), (run, signum)
        left = sorted(p.name for p in folder.iterdir())
        assert left in ([], [output]), left
        assert not left or same_output(folder / output, reference / output)
        outcomes.append("output whole" if left else "no output")
    print(f"{name}: {duration:.1f} s a run; {outcomes}")
