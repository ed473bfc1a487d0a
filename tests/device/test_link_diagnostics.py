"""What the serial link and the session say about outages is true: frames the device
sent before anyone listened are not lost frames, a failure that is over is not the last error,
a link lost while idle is reported, a cycle on a port that never opened says why, and a
restarted device's samples are counted as missing from their indices."""

import numpy as np
import pytest

from device.spy import SpyDevice
from device.test_emulator import CAP_A, SCENARIO, collect, samples_of, wait_for
from mows.device.backends.serial_backend import SerialBackend
from mows.device.cycle.phases import CycleRequest, CycleSettings
from mows.device.interface import LinkEvent
from mows.device.serial.emulator import DeviceEmulator
from mows.device.serial.link import SerialLink
from mows.device.stream.blocks import BlockAssembler
from mows.device.stream.session import DeviceSession, SessionConfig
from mows.estimate.ringdown import fit_tuning
from mows.physics.coils import CurrentCap
from mows.records.samples import SampleBlock

SETTINGS = CycleSettings(excite_s=0.3, ringdown_s=0.3, gap_s=0.1, repeats=1, tuning_steps=0, turn_settle_s=0.1)


def session_on(link):
    return DeviceSession(
        SerialBackend(link, CurrentCap(CAP_A)),
        SessionConfig(0.025, SETTINGS, SCENARIO.setup, CurrentCap(CAP_A), 110.0, fit_tuning),
    )


def chunk(first, n=100):
    return SampleBlock(first, first * 50_000, 20_000.0, np.zeros((n, 2)), np.zeros((n, 2), bool))


def test_a_restarted_device_counts_its_samples_before_the_first_received_as_missing():
    assembler = BlockAssembler(500)
    for first in range(200_000, 201_000, 100):  # 10 s after the device's boot
        assembler.add(chunk(first))
    assembler.add(chunk(140_000))  # it restarted 7 s ago: its index started again at 0
    assert (assembler.gaps, assembler.restarts) == (1, 1)
    assert assembler.missing_samples == 140_000  # not "0 samples missing" after a 7 s outage
    # The blocks before the restart are of the first clock, those after it of the next: a
    # subscriber starts its stream again instead of taking them for repeats of the old.
    published = assembler.flush() + [b for first in range(140_100, 141_100, 100) for b in assembler.add(chunk(first))]
    assert [b.epoch for b in published] == [1, 1, 1]
    assert BlockAssembler(500, first_epoch=3).epoch == 3  # a driver reconfigured goes on counting


def test_frames_the_device_sent_before_the_first_connection_are_not_lost(tmp_path):
    with DeviceEmulator(SpyDevice(SCENARIO), tmp_path / "device", CurrentCap(CAP_A)) as emulator:
        # Nobody reads: the pty fills and the device drops frames, as one streaming from power-on.
        wait_for(lambda: emulator.dropped_frames > 0, "the device to drop frames")
        link = SerialLink(str(emulator.link_path)).start()
        try:
            collect(link, "20 Samples frames after the answer", lambda items: link.up and len(samples_of(items)) >= 20)
            assert link.lost_frames == 0
        finally:
            link.close()


def test_the_last_error_is_cleared_once_the_link_is_up_and_loss_is_reported_while_idle(tmp_path):
    path = tmp_path / "device"
    link = SerialLink(str(path)).start()
    session = session_on(link)
    try:
        wait_for(lambda: link.open_failures > 0, "an attempt to open the absent port")
        assert "cannot open" in link.stats()["last_error"]
        with pytest.raises(ValueError, match="has not answered yet .*cannot open"):
            session.start_cycle(CycleRequest(0.0), lambda outcome: None)
        with DeviceEmulator(SpyDevice(SCENARIO), path, CurrentCap(CAP_A)) as emulator:
            links = []
            wait_for(lambda: session.link_up, "the link to come up", lambda: links.extend(session.step(0.05).links))
            assert link.stats()["last_error"] == ""  # not the stale "cannot open"
            emulator.unplug()  # no cycle is running: the session is idle
            wait_for(lambda: not session.link_up, "the link to go down", lambda: links.extend(session.step(0.05).links))
        # The absent port was reported once (not once per retry), before the device answered.
        assert [event.up for event in links] == [False, True, False]
        assert "cannot open" in links[0].reason
        assert all(isinstance(event, LinkEvent) and event.reason for event in links)
    finally:
        session.close()
