"""Signals always win: SIGTERM or SIGINT at any moment ends a command with one line and 143 or 130.

Requirement: whenever the signal comes, from the moment the command can catch it until it has
settled its status (the interpreter's own start, before any of the command's code runs, is the
operating system's default: the process dies by the signal, which a shell reports as 143 or 130
too), the command exits 143 (SIGTERM) or 130 (SIGINT), says so in exactly one line on stderr,
and leaves its output either absent or whole (the bytes of an uninterrupted run), never
half-written, no temporary or journal behind, and never claims an output ("wrote …") that is
not there. A signal that finds the command already done (its status settled, its handlers
gone) changes nothing: status 0 and the whole output.

The moments are random and uniform over the command's work, measured in the CPU time of its
process (``/proc/PID/schedstat``), so that a loaded machine, which stretches the wall clock,
moves no moment out of the run. Most runs are forked from a server process that has imported
what the command imports (each a real process of its own, getting a real signal from outside,
from ``main()`` on: the command as its console script runs it), many at once; that makes a run
short and a hundred affordable. A few runs are fresh interpreters, whose moments also cover the
imports. MOWS_KILL_RUNS sets the number of forked runs of each command (default
:data:`FORKED_RUNS`).
"""

import dataclasses
import json
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
# Forked runs per command, a hundred in all: fewer of the report, whose run costs six times the
# simulation's CPU time (mostly its figures), so that the suite's time grows by a minute at most.
FORKED_RUNS = {"lab-report": 30, "sim": 70}
FRESH_RUNS = 2  # per command, in fresh interpreters
AT_ONCE = 6  # runs alive at a time
COMMANDS = {
    "lab-report": (["lab", "report", str(SWEEP_TABLE), "--no-cv", "-o"], "r.html"),
    "sim": (["sim", "--repeats", "2", "--seed", "3", "--out"], "x.npz"),
}
STATUS = {signal.SIGTERM: 143, signal.SIGINT: 130}
WORDS = {signal.SIGTERM: "terminated", signal.SIGINT: "interrupted"}


def environment(folder: pathlib.Path) -> dict[str, str]:
    """Every run's: one BLAS thread (forking a process with a thread pool is unsafe, and the forked
    and the fresh runs must compute the same bytes) and figures without a date or a random salt
    for their ids (matplotlib's SVG), so that two whole runs are the same bytes."""
    (folder / "matplotlibrc").write_text("svg.hashsalt: mows\n")
    threads = {name: "1" for name in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    return {**os.environ, **threads, "SOURCE_DATE_EPOCH": "0", "MATPLOTLIBRC": str(folder / "matplotlibrc")}


SERVER = r"""
import atexit, json, os, signal, sys, traceback
from mows.cli.main import main

def child(request):
    os.chdir(request["cwd"])
    for fd, path, flags in ((0, os.devnull, os.O_RDONLY), (1, request["stdout"], os.O_WRONLY | os.O_CREAT),
                            (2, request["stderr"], os.O_WRONLY | os.O_CREAT)):
        opened = os.open(path, flags, 0o644)
        os.dup2(opened, fd)
        os.close(opened)
    # as from a terminal, whatever this server inherited (a background job's SIGINT is ignored)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if request.get("modules"):
        atexit.register(lambda: open(request["modules"], "w").write("\n".join(sorted(sys.modules))))
    sys.argv = ["mows", *request["argv"]]
    try:
        status = main()  # ends the process itself (os._exit); if not, as the console script would
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:
        traceback.print_exc()
        status = 1
    os._exit(status)

for line in sys.stdin:
    request = json.loads(line)
    if "run" in request:
        pid = os.fork()
        if pid == 0:
            child(request["run"])
        answer = {"pid": pid}
    elif "wait" in request:
        _, status, usage = os.wait4(request["wait"], 0)
        answer = {"status": os.waitstatus_to_exitcode(status), "cpu_s": usage.ru_utime + usage.ru_stime}
    else:  # what a run imported, so that the runs forked from here start with it
        for name in request["load"]:
            try:
                __import__(name)
            except Exception:
                pass
        answer = {}
    sys.stdout.write(json.dumps(answer) + "\n")
    sys.stdout.flush()
"""


class Server:
    """A process that forks runs of ``mows`` on request and reports their exit."""

    def __init__(self, env: dict[str, str]) -> None:
        self.env = env
        command = [sys.executable, "-c", SERVER]
        self.process = subprocess.Popen(command, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env)

    def ask(self, **request) -> dict:
        self.process.stdin.write(json.dumps(request) + "\n")
        self.process.stdin.flush()
        return json.loads(self.process.stdout.readline())

    def close(self) -> None:
        self.process.stdin.close()
        self.process.wait(timeout=60)


def proc(pid: int, name: str) -> str:
    try:
        return pathlib.Path(f"/proc/{pid}/{name}").read_text()
    except OSError:  # gone (reaped): ended
        return ""


def ended(pid: int) -> bool:
    stat = proc(pid, "stat")
    return not stat or stat[stat.rindex(")") + 2] == "Z"


def cpu_s(pid: int) -> float:
    """The CPU time the process's main thread has had, s."""
    schedstat = proc(pid, "schedstat")
    return int(schedstat.split()[0]) * 1e-9 if schedstat else 0.0


def handles(pid: int, signum: int) -> bool:
    """Whether ``signum`` reaches a handler of the command: caught (Linux's SigCgt mask), not
    yet ignored (as from the moment its status is settled)."""
    masks = dict(line.split(":\t") for line in proc(pid, "status").splitlines() if line.startswith("Sig"))
    bit = 1 << (signum - 1)
    return bool(masks and int(masks["SigCgt"], 16) & bit and not int(masks["SigIgn"], 16) & bit)


@dataclasses.dataclass
class Run:
    """One run of the command in its own folder, and the moment (the process's CPU time) it gets
    ``signum`` at."""

    folder: pathlib.Path
    signum: int
    moment_s: float
    pid: int = 0
    fresh: subprocess.Popen | None = None
    sent: bool = False

    def streams(self) -> tuple[pathlib.Path, pathlib.Path]:
        return self.folder.with_suffix(".out"), self.folder.with_suffix(".err")


def start(run: Run, argv: list[str], server: Server, fresh: bool) -> Run:
    run.folder.mkdir()
    out, err = run.streams()
    if not fresh:
        run.pid = server.ask(run={"argv": argv, "cwd": str(run.folder), "stdout": str(out), "stderr": str(err)})["pid"]
        return run
    command = ["env", "--default-signal=INT", sys.executable, "-m", "mows.cli.main", *argv]
    with open(out, "w") as stdout, open(err, "w") as stderr:
        run.fresh = subprocess.Popen(command, cwd=run.folder, stdout=stdout, stderr=stderr, env=server.env)
    run.pid = run.fresh.pid
    return run


def status(run: Run, server: Server) -> int:
    if run.fresh is not None:
        return run.fresh.wait(timeout=60)
    return server.ask(wait=run.pid)["status"]


def signal_at_moments(runs: list[Run], argv: list[str], server: Server, fresh: bool) -> list[tuple[Run, int]]:
    """Every run started (forked from ``server``, or ``fresh`` interpreters; AT_ONCE alive at a
    time) and sent its signal once its CPU time reaches
    its moment; (run, exit status) of each once it has ended."""
    waiting, alive, done = list(runs), [], []
    deadline = time.monotonic() + 600
    while waiting or alive:
        while waiting and len(alive) < AT_ONCE:
            alive.append(start(waiting.pop(0), argv, server, fresh))
        for run in list(alive):
            if ended(run.pid):
                alive.remove(run)
                done.append((run, status(run, server)))
            elif not run.sent and cpu_s(run.pid) >= run.moment_s and handles(run.pid, run.signum):
                os.kill(run.pid, run.signum)
                run.sent = True
        assert time.monotonic() < deadline, [run.folder.name for run in alive]
        time.sleep(0.005)  # a moment late by this much: still one of the run's
    return done


def same_output(path: pathlib.Path, reference: pathlib.Path) -> bool:
    if path.suffix == ".npz":
        with np.load(path) as got, np.load(reference) as want:
            return sorted(got) == sorted(want) and all(
                np.array_equal(got[k], want[k], equal_nan=want[k].dtype.kind in "fc") for k in want
            )
    return path.read_bytes() == reference.read_bytes()


def check(name: str, run: Run, status: int, output: str, reference: Run) -> str:
    """What the run left, checked; its outcome in a word."""
    err, out = (path.read_text() for path in reversed(run.streams()))
    left = sorted(p.name for p in run.folder.iterdir())
    where = (run.folder.name, run.signum.name, f"{run.moment_s:.3f} s", run.sent)
    assert left in ([], [output]), (where, left)  # no temporary, no journal, nothing else
    assert not left or same_output(run.folder / output, reference.folder / output), where
    assert f"wrote {output}" not in out or left, (where, out)  # said done only when it is
    if not run.sent:  # its work done before the moment came: as an uninterrupted run
        assert (status, err, left) == (0, reference.streams()[1].read_text(), [output]), (where, status, err)
        return "done first"
    assert (status, err) == (STATUS[run.signum], f"mows {name.replace('-', ' ')}: {WORDS[run.signum]}\n"), where
    return "whole output" if left else "no output"


@pytest.mark.slow  # ~80 CPU-s for the report, ~20 for the simulation (docs/performance.md)
@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_a_signal_at_a_random_moment_ends_the_command_with_one_line(tmp_path, name):
    argv, output = COMMANDS[name]
    argv = [*argv, output]
    count = int(os.environ.get("MOWS_KILL_RUNS", FORKED_RUNS[name]))
    server = Server(environment(tmp_path))
    try:
        # Uninterrupted: a run forked from the bare server (the reference output, and the CPU
        # time of a whole run with its imports), which lists the modules it loaded; the server
        # loads them, and a run forked then gives the CPU time of a run without its imports.
        modules = tmp_path / "modules.txt"
        reference, cold_s = uninterrupted(tmp_path / "reference", argv, server, modules)
        server.ask(load=modules.read_text().split())
        warm, warm_s = uninterrupted(tmp_path / "warm", argv, server)
        assert same_output(warm.folder / output, reference.folder / output)
        rng = random.Random(f"{name}-{count}")

        def runs(count: int, prefix: str, whole_s: float) -> list[Run]:
            return [
                Run(tmp_path / f"{prefix}{i}", rng.choice(list(STATUS)), rng.uniform(0.0, 1.1 * whole_s))
                for i in range(count)
            ]

        forked = signal_at_moments(runs(count, "forked", warm_s), argv, server, fresh=False)
        fresh = signal_at_moments(runs(FRESH_RUNS, "fresh", cold_s), argv, server, fresh=True)
    finally:
        server.close()
    outcomes = [check(name, run, status, output, reference) for run, status in forked + fresh]
    assert len(outcomes) == count + FRESH_RUNS
    print(f"{name}: a whole run {warm_s:.2f} CPU-s forked, {cold_s:.2f} with its imports;")
    print({outcome: outcomes.count(outcome) for outcome in sorted(set(outcomes))})


def uninterrupted(folder: pathlib.Path, argv: list[str], server: Server, modules=None) -> tuple[Run, float]:
    """A run forked from the server and left to finish (``modules``: the file it lists the
    modules it loaded in), and its CPU time."""
    run = Run(folder, signal.SIGTERM, 0.0)
    folder.mkdir()
    out, err = run.streams()
    request = {"argv": argv, "cwd": str(folder), "stdout": str(out), "stderr": str(err)}
    run.pid = server.ask(run={**request, "modules": modules and str(modules)})["pid"]
    ended = server.ask(wait=run.pid)
    assert ended["status"] == 0, err.read_text()
    return run, ended["cpu_s"]


DISCARDED = """
import os, signal, sys, time, weakref
from mows.cli import status
status.stop_on_signals()
class Thing:
    pass
thing = Thing()
seen = weakref.ref(thing, lambda _: os.kill(os.getpid(), signal.SIGTERM))  # raised in there: discarded
try:
    del thing
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        pass
    print("not interrupted")
except KeyboardInterrupt as error:
    print(type(error).__name__)
"""


@pytest.mark.parametrize("attempt", range(3))
def test_an_interrupt_python_discards_is_raised_again_after_the_hook(attempt):
    """SIGTERM handled inside a weakref callback, where Python discards the exception: the
    command's next bytecode outside the hook gets it, and nothing is said of the discarded one."""
    run = subprocess.run([sys.executable, "-c", DISCARDED], capture_output=True, text=True, timeout=120)
    assert (run.stdout, run.stderr) == ("Terminated\n", ""), run.stderr


DEBRIS = """
import os, signal, sys
from mows.cli import status
status.stop_on_signals()
class HalfBuilt:  # as llvmlite's ObjectRef, cut short while it was made
    def __del__(self):
        raise AttributeError("_as_parameter_")
try:
    thing = HalfBuilt()
    os.kill(os.getpid(), signal.SIGTERM)
except KeyboardInterrupt as error:
    line, code = status.interrupted("mows sim", error)
    print(line, file=sys.stderr)
    del thing  # its __del__ fails after the line, as at the interpreter's exit
    sys.exit(code)
"""


def test_the_debris_of_work_a_signal_cut_short_adds_nothing_to_the_line():
    """A first run compiles numba's kernels; SIGTERM in the middle leaves a half-built object
    whose __del__ fails as the interpreter ends. The command still ends with its one line."""
    run = subprocess.run([sys.executable, "-c", DEBRIS], capture_output=True, text=True, timeout=120)
    assert (run.returncode, run.stderr) == (143, "mows sim: terminated\n"), run.stderr


def test_an_error_in_a_del_without_a_signal_is_still_reported():
    """Without a signal, the same failing __del__ is a bug of ours and is said as Python says it."""
    code = DEBRIS.replace("    os.kill(os.getpid(), signal.SIGTERM)\n", "    raise KeyboardInterrupt\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "AttributeError: _as_parameter_" in run.stderr, run.stderr


HALF_LOADED = """
import ctypes, os, signal
from mows.cli import status
from mows.cli.inputs import report_errors
status.stop_on_signals()
class HalfLoaded:  # as a numba kernel cut short while it loaded: its C objects crash when freed
    def __del__(self):
        ctypes.string_at(0)
def work():
    kernel = HalfLoaded()
    os.kill(os.getpid(), signal.SIGTERM)
    while kernel:
        pass
os._exit(status.settle("mows sim", report_errors("mows sim", work)))
"""


def test_the_work_a_signal_cut_short_is_never_taken_apart():
    """What the signal cut short is not freed after the line (the process ends with it whole): a
    half-loaded kernel whose freeing would crash leaves the status and the line as they are."""
    run = subprocess.run([sys.executable, "-c", HALF_LOADED], capture_output=True, text=True, timeout=120)
    assert (run.returncode, run.stderr) == (143, "mows sim: terminated\n"), run.stderr


SWALLOWED = """
import os, signal
from mows.cli import status
from mows.cli.inputs import report_errors
status.stop_on_signals()
def work():
    try:  # a library that takes the interrupt for its own failure, then fails on its half-done state
        os.kill(os.getpid(), signal.SIGTERM)
        while True:
            pass
    except BaseException:
        pass
    raise {error}("Invalid bounding box")
os._exit(status.settle("mows lab report", report_errors("mows lab report", work)))
"""


@pytest.mark.parametrize("error", ["ValueError", "RuntimeError"])
def test_an_error_that_a_signal_left_behind_is_not_said(error):
    """The signal wins in one line: the error a library raises after swallowing it (matplotlib's
    'Invalid bounding box' once) is what the signal cut short, a bad input or a bug alike."""
    code = SWALLOWED.format(error=error)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert (run.returncode, run.stderr) == (143, "mows lab report: terminated\n"), run.stderr
