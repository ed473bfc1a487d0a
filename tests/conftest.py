"""Session set-up for the whole suite.

This runs when pytest imports it, before any test module imports rclpy, because the DDS
middleware reads its settings once per process (and the nodes that tests start inherit
them): traffic stays on this host, in a ROS domain that no other test run on this machine
uses at the same time.
"""

import fcntl
import os

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
    """Slow tests first: pytest-xdist hands the first test to the first worker, so the 60 s
    live stream (mostly waiting on the real-time device) runs while the other worker goes
    through the rest, instead of alone at the end."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


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
