"""Session set-up for the whole suite.

This runs when pytest imports it, before any test module imports rclpy, because the DDS
middleware reads its settings once per process (and the nodes that tests start inherit
them): traffic stays on this host, in a ROS domain that no other test run on this machine
uses at the same time.
"""

import faulthandler
import fcntl
import os
import resource
import sys
import time

import pytest

DOMAIN_IDS = range(1, 102)  # the ids whose DDS ports are safe on Linux
DOMAIN_LOCK = "/tmp/mows-ros-domain-{}.lock"


def claim_domain() -> tuple[int, object]:
    """The first domain id whose lock file no other process holds, and the open lock.

    The kernel drops the lock when the process ends, so a crashed run frees its domain.
    """
    for domain in DOMAIN_IDS:
        lock = open(DOMAIN_LOCK.format(domain), "a")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return domain, lock
    raise RuntimeError(f"every ROS domain in {DOMAIN_IDS} is held by another test run")


# One BLAS thread per process, here and in every process a test starts: three workers share two
# cores, so OpenBLAS's second thread never has a core of its own, and its threads spin waiting
# for each other (a workspace map's fit took 25 CPU-s with two threads, 9 with one). Read when
# numpy loads OpenBLAS, so before any test module imports numpy.
for _threads in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS"):  # numpy's and scipy's OpenBLAS; scikit-learn's OpenMP
    os.environ.setdefault(_threads, "1")

os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
DOMAIN_ID, _domain_lock = claim_domain()  # held open for the whole session
os.environ["ROS_DOMAIN_ID"] = str(DOMAIN_ID)


@pytest.fixture(scope="session", autouse=True)
def compiled_kernels():
    """The numba kernels compiled (or loaded from the cache) once, before any test: on a fresh
    checkout the first fit would otherwise take ~10 s inside whatever test comes first, and a
    device link that waits on it would time out."""
    from mows.precompile import precompile

    precompile()


def pytest_collection_modifyitems(items: list) -> None:
    """Slow tests first: pytest-xdist (--dist=loadgroup) hands out the xdist groups first, the
    largest first, then the other tests in this order, so that a long one (the live stream,
    mostly waiting on the real-time device) starts early instead of alone at the end."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


# pytest-timeout fails a test after 600 s (pyproject.toml) by a signal, which Python hears only
# when the main thread runs bytecode again: a call blocked inside C (a DDS wait, a lock taken in
# an extension) never lets it. This watchdog runs in a C thread of its own: it writes every
# thread's stack to stderr and ends the worker, so that the run reports a crashed worker and
# stops, with the stack that hung, instead of waiting until CI kills it.
HUNG_TEST_S = 720.0
HUNG_EXIT_S = 120.0  # after the last test: threads or children that keep a worker from exiting


_stderr = None  # the process's own stderr, which pytest's capture does not redirect


def pytest_configure(config) -> None:
    global _stderr
    _stderr = os.fdopen(os.dup(sys.stderr.fileno()), "w")


# MOWS_TEST_CPU_LOG=FILE: each test's CPU seconds (its worker's and those of the processes it
# started and waited for), setup and teardown included, appended to FILE as tab-separated lines
# "node id, user + system of the worker, of its children, wall". The suite is CPU-bound on two
# cores, so this is the figure to cut; wall times move with the shared machine's load.
CPU_LOG = os.environ.get("MOWS_TEST_CPU_LOG")


def _cpu_s(who: int) -> float:
    usage = resource.getrusage(who)
    return usage.ru_utime + usage.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    faulthandler.dump_traceback_later(HUNG_TEST_S, exit=True, file=_stderr)
    start = (_cpu_s(resource.RUSAGE_SELF), _cpu_s(resource.RUSAGE_CHILDREN), time.perf_counter())
    yield
    faulthandler.cancel_dump_traceback_later()
    if CPU_LOG:
        end = (_cpu_s(resource.RUSAGE_SELF), _cpu_s(resource.RUSAGE_CHILDREN), time.perf_counter())
        with open(CPU_LOG, "a") as log:
            log.write("\t".join([item.nodeid, *(f"{b - a:.2f}" for a, b in zip(start, end))]) + "\n")


def pytest_unconfigure(config) -> None:
    faulthandler.dump_traceback_later(HUNG_EXIT_S, exit=True, file=_stderr)


def pytest_report_header() -> str:
    return f"ROS_DOMAIN_ID={DOMAIN_ID}, ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST"


@pytest.fixture
def ros_context():
    """rclpy's default context, initialised for one test and shut down after it.

    Signal handlers stay pytest's, so that Ctrl-C still interrupts the run.
    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    yield rclpy.get_default_context()
    rclpy.try_shutdown()
