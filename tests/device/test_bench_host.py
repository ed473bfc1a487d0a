"""The paper's bench on a busy host (NI's ``nidaqmx`` on the simulated card, the NGM202 through
pyvisa-sim).

Requirement: the threads that feed the card (the one that polls it, the supply's, the watchdog)
run under SCHED_FIFO at the device file's priority where the system allows it, the poller put
back to its own policy when the bench closes, and where it refuses the bench streams on at the
default policy and says why; a switch-off reaches the coils at once, not after the output lead
that a drive is written ahead.
"""

import os
import threading

from device.test_bench_backends import blocks, drive, poll_for, simulated_supply
from mows.device.backends.realtime import Priority
from mows.device.interface import DeviceFault, LinkEvent


def policy(thread) -> tuple[int, int]:
    return os.sched_getscheduler(thread.native_id), os.sched_getparam(thread.native_id).sched_priority


def test_the_threads_that_feed_the_card_run_under_sched_fifo_and_the_poller_is_put_back(on_bench):
    """The poller (the driver's stream thread), the supply's thread and the watchdog under the
    device file's SCHED_FIFO priority while the card is open; the poller at its own after."""
    before = policy(threading.current_thread())
    _, backend = on_bench("calibration", simulated_supply())
    assert backend.device.realtime_priority == 40  # the paper's file
    backend.poll(0.05)
    fifo = (os.SCHED_FIFO, 40)
    assert policy(threading.current_thread()) == fifo
    assert policy(backend.supply_line._thread) == fifo and policy(backend._watchdog) == fifo
    assert backend.stats()["realtime"] == "SCHED_FIFO 40"
    backend.close()
    assert policy(threading.current_thread()) == before


def test_where_sched_fifo_is_refused_the_bench_streams_at_the_default_policy_and_says_why(on_bench, monkeypatch):
    def refuses(*args):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuses)
    before = policy(threading.current_thread())
    _, backend = on_bench("calibration", simulated_supply())
    items = poll_for(backend, 0.2)
    assert blocks(items) and not [i for i in items if isinstance(i, LinkEvent)]
    assert policy(threading.current_thread()) == before
    assert backend.stats()["realtime"].startswith("SCHED_FIFO 40 refused (Operation not permitted)")
    backend.close()


def test_a_switch_off_reaches_the_coils_at_once_not_after_the_lead(on_bench):
    """A drive is written the output lead (2 s) ahead of the sample the card generates: a
    cancel's or an emergency stop's switch-off cuts it at once, and the stream goes on."""
    card, backend = on_bench()
    items: list = []
    on, off = drive(backend, items, duration_s=3.0)
    while not card.drives or card.sample_now <= on:  # the coils are driven now
        items += backend.poll(0.05)
    before = card.sample_now
    backend.coils_off_now()
    after = card.sample_now
    items += poll_for(backend, 0.2)
    assert card.drives == card.drives[:1] and len(card.offs) == 1
    assert before <= card.offs[0] <= after < off  # off before coils_off_now returned
    assert backend.card_faults == 0 and not [i for i in items if isinstance(i, (LinkEvent, DeviceFault))]
    assert blocks(items)[-1].first_sample_index > after  # the stream goes on
    backend.close()


def test_a_thread_two_benches_raise_is_put_back_to_its_own_policy_whichever_closes_first():
    before = policy(threading.current_thread())
    first, second = Priority(40), Priority(40)
    assert first.raise_thread() and second.raise_thread()
    first.restore()
    second.restore()
    assert policy(threading.current_thread()) == before
