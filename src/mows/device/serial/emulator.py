"""The MOWS device on a pseudo-terminal, speaking docs/serial_protocol.md, backed by the
simulator: the serial backend is tested end to end with no hardware.

    python -m mows.device.serial.emulator --link /tmp/mows-device [--scenario NAME_OR_YAML]

The emulator opens a pty (``os.openpty``) and points a symbolic link at its terminal, so that
the host always opens the same path, also after :meth:`DeviceEmulator.unplug` and
:meth:`DeviceEmulator.replug` (which close the pty and open a new one, as a USB device that
is pulled out and plugged in again). Its sample clock keeps running while it is unplugged:
the samples of that time are lost, and the host sees the jump of the sample index and of the
frame sequence. The link is made only where nothing is (an existing file, link or directory at
the path is refused, exit status 2) and removed only while it is still the emulator's own.

Like the hardware it:

* takes samples in real time (:class:`mows.device.clock.DeviceClock`) and sends them in
  Samples frames of ``frame_samples``, a Status frame every STATUS_PERIOD_S of device time;
* applies coil and orientation commands at their sample (:class:`ScheduledDevice`) and acks
  each with the sample it applies at, refusing currents above its cap;
* ramps its static-field supply (a scenario with a ``supply`` section) on FieldCurrent frames,
  within the supply's cap and slew limit, and acks each with the sample the ramp ends;
* switches the coils off and ramps the supply to zero when no host frame has arrived for
  ``watchdog_timeout_s`` (a host that died mid-calibration leaves no field on): the off
  takes effect exactly at the sample where the deadline falls (a host frame is stamped with
  the sample clock when it is read, at most one loop period, ``frame_samples``, late).
  The device's own coil log (:attr:`ScheduledDevice.coil_log`, from the samples' coil flags)
  and :attr:`watchdog_trips` show it.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import signal
import sys
import threading
import tty
from pathlib import Path

import numpy as np

from mows.device.clock import DeviceClock
from mows.device.interface import CoilTone
from mows.device.protocol.framing import Frame, FrameDecoder, encode_frame
from mows.device.protocol.payloads import (
    Ack,
    Body,
    Coils,
    DeviceInfo,
    FieldCurrent,
    Heartbeat,
    Hello,
    Orientation,
    Samples,
    Status,
)
from mows.device.simulated.scheduled import OverCap, ScheduledDevice
from mows.physics.coils import CurrentCap
from mows.sim.scenario import load_scenario
from mows.sim.simulator import SimulatedDevice

WATCHDOG_TIMEOUT_S = 0.15  # with host heartbeats every 50 ms; the bound is 200 ms
FRAME_S = 0.01  # samples per Samples frame, in seconds of device time
STATUS_PERIOD_S = 0.1
OUTPUT_LIMIT_BYTES = 256 * 1024  # frames waiting for a host that does not read (~1.5 s); more are dropped
READ_BYTES = 65536
MIN_WATCHDOG_S = FRAME_S


class DeviceEmulator:
    """``device`` behind a pty whose path is the symbolic link ``link_path``."""

    def __init__(
        self,
        device: SimulatedDevice,
        link_path: str | os.PathLike,
        cap: CurrentCap = CurrentCap(),
        watchdog_timeout_s: float = WATCHDOG_TIMEOUT_S,
        clock: DeviceClock | None = None,
    ):
        if not (math.isfinite(watchdog_timeout_s) and watchdog_timeout_s >= MIN_WATCHDOG_S):
            raise ValueError(
                f"watchdog timeout {watchdog_timeout_s!r} s is out of range: at least {MIN_WATCHDOG_S:g} s "
                "(one frame of the device loop), or the coils would switch off between any two host frames"
            )
        self.device = ScheduledDevice(device, cap)
        self.link_path = Path(link_path)
        self.clock = clock or DeviceClock(device.sample_rate_hz)
        rate = device.sample_rate_hz
        self.frame_samples = round(FRAME_S * rate)
        self._watchdog_samples = round(watchdog_timeout_s * rate)
        self._status_samples = round(STATUS_PERIOD_S * rate)
        near = device.scenario.sensors.pair.sensors[0]
        self.info = DeviceInfo(
            rate, 2, device.n_coils, near.range_t, near.resolution_t, self.device.cap.limit_a, watchdog_timeout_s
        )
        self.watchdog_trips: list[tuple[int, int]] = []  # (sample of the last host frame, sample of coils off)
        # Host silences of at least the watchdog time: (sample of the last frame, of the next).
        self.long_silences: list[tuple[int, int]] = []
        self.dropped_frames = 0
        self.misdirected_frames = 0
        self.decoder = FrameDecoder()
        self._sequence = 0
        self._last_host_index = 0
        self._tripped_for: int | None = None  # the last-host index a trip was for
        self._next_status = 0
        self._fds: tuple[int, int] | None = None  # (master, slave) while plugged
        self._output = bytearray()
        self._lock = threading.Lock()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._loop, name="mows-device-emulator", daemon=True)

    # --- life ------------------------------------------------------------------------------
    def start(self) -> DeviceEmulator:
        with self._lock:
            self._plug()
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stopping.set()
        self._thread.join()
        with self._lock:
            self._unplug()

    def __enter__(self) -> DeviceEmulator:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    @property
    def plugged(self) -> bool:
        return self._fds is not None

    def unplug(self) -> None:
        """Pull the cable: the pty closes (the host's reads fail), the link path disappears."""
        with self._lock:
            self._unplug()

    def replug(self) -> None:
        """Plug it in again: a new pty behind the same link path."""
        with self._lock:
            self._plug()

    def _plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # a byte pipe: no echo, no line editing, no CR/LF translation
        os.set_blocking(master, False)
        try:  # never over what is there: os.symlink refuses an existing path atomically
            os.symlink(os.ttyname(slave), self.link_path)
        except OSError as error:
            os.close(master)
            os.close(slave)
            if isinstance(error, FileExistsError):
                raise FileExistsError(
                    f"device emulator: {self.link_path} exists: it is not this emulator's link; "
                    "remove it or choose another --link path"
                ) from None
            raise OSError(f"device emulator: cannot make the link {self.link_path}: {error.strerror}") from None
        self._fds = (master, slave)

    def _own_link(self) -> bool:
        """The link path is still the symbolic link to this emulator's terminal."""
        return (
            self._fds is not None
            and self.link_path.is_symlink()
            and os.readlink(self.link_path) == os.ttyname(self._fds[1])
        )

    def _unplug(self) -> None:
        if self._fds is None:
            return
        if self._own_link():  # a file someone put there meanwhile is not ours to delete
            self.link_path.unlink()
        for fd in self._fds:
            os.close(fd)
        self._fds = None
        self._output.clear()
        self.decoder.finish()  # a host frame cut by the unplug is counted as truncated

    # --- the device's loop -----------------------------------------------------------------
    def _loop(self) -> None:
        while not self._stopping.is_set():
            with self._lock:
                due = self.clock.due_index()
                self._take_samples(due)
                self._receive(due)
                self._flush()
                fds = self._fds
            self._wait(fds)

    def _wait(self, fds) -> None:
        timeout = self.clock.seconds_until(self.device.next_index + self.frame_samples)
        if fds is None:
            self._stopping.wait(timeout)
            return
        try:
            select.select([fds[0]], [fds[0]] if self._output else [], [], timeout)
        except (OSError, ValueError):  # unplugged meanwhile: the descriptor is gone
            pass

    def _take_samples(self, due: int) -> None:
        while due - self.device.next_index >= self.frame_samples:
            end = self.device.next_index + self.frame_samples
            self._watchdog(end)
            first = self.device.next_index
            blocks = self.device.read_until(end)
            samples = np.concatenate([b.samples.samples_t for b in blocks])
            counts = np.round(samples / self.info.resolution_t).astype(np.int32)
            self._send(
                Samples(first, counts, np.concatenate([b.samples.saturated for b in blocks])),
                self.clock.stamp_ns(first),
            )
            if end >= self._next_status:
                self._send(self.status(), self.clock.stamp_ns(end))
                self._next_status = end + self._status_samples

    def _watchdog(self, end: int) -> None:
        """Coils off at the sample where the host's silence reaches the timeout."""
        deadline = self._last_host_index + self._watchdog_samples
        supply_on = self.device.supply_limits is not None and (
            self.device.supply_target_a != 0.0 or self.device.device.field_current_a != 0.0
        )
        if deadline < end and (self.device.busy or supply_on) and self._tripped_for != self._last_host_index:
            off = self.device.switch_off_at(deadline)
            self.device.supply_to_zero()
            self.watchdog_trips.append((self._last_host_index, off))
            self._tripped_for = self._last_host_index
            # Told before the samples in which the coils go off, so the host never takes
            # them for a ring-down it scheduled.
            self._send(self.status(), self.clock.stamp_ns(self.device.next_index))

    def silent_since(self) -> int | None:
        """The sample of the host's last frame if its silence has reached the watchdog time."""
        if self.device.next_index - self._last_host_index >= self._watchdog_samples:
            return self._last_host_index
        return None

    def status(self) -> Status:
        return Status(
            self.device.next_index,
            self.device.coils_on,
            len(self.watchdog_trips),
            self.dropped_frames,
            self.decoder.rejected_total + self.misdirected_frames,
        )

    # --- frames ----------------------------------------------------------------------------
    def _receive(self, due: int) -> None:
        if self._fds is None:
            return
        data = b""
        while True:
            try:
                chunk = os.read(self._fds[0], READ_BYTES)
            except (BlockingIOError, OSError):
                break
            if not chunk:
                break
            data += chunk
        for frame in self.decoder.feed(data):
            if due - self._last_host_index >= self._watchdog_samples:
                self.long_silences.append((self._last_host_index, due))
            self._last_host_index = due
            self._handle(frame, due)

    def _handle(self, frame: Frame, due: int) -> None:
        body = frame.body
        if isinstance(body, Hello):
            self._send(self.info, self.clock.stamp_ns(due))
        elif isinstance(body, (Coils, Orientation, FieldCurrent)):
            result, applied = self._command(body)
            self._send(Ack(frame.sequence, result, applied), self.clock.stamp_ns(due))
        elif not isinstance(body, Heartbeat):
            self.misdirected_frames += 1  # a device's frame type, sent to the device

    def _command(self, body: Coils | Orientation | FieldCurrent) -> tuple[int, int]:
        """(Ack result, applied sample) of a host command."""
        try:
            if isinstance(body, FieldCurrent):
                return self._supply(body)
            if isinstance(body, Orientation):
                return Ack.OK, self.device.schedule_orientation(body.at_sample_index, body.theta0_rad)
            tones = (CoilTone(0, body.frequency_hz, body.amplitudes_a),)  # the protocol's one tone
            self.device.check_coils(tones)
            if body.immediate:
                self.device.cancel()
            return Ack.OK, self.device.schedule_coils(0 if body.immediate else body.at_sample_index, tones)
        except OverCap:
            return Ack.REFUSED_OVER_CAP, 0
        except ValueError:
            return Ack.REFUSED_INVALID, 0
        except RuntimeError:
            return Ack.REFUSED_BUSY, 0

    def _supply(self, body: FieldCurrent) -> tuple[int, int]:
        limits = self.device.supply_limits
        if limits is None:
            return Ack.REFUSED_INVALID, 0
        if body.to_zero_now:
            return Ack.OK, self.device.supply_to_zero()
        if abs(body.current_a) > limits.cap_a:
            return Ack.REFUSED_OVER_CAP, 0
        return Ack.OK, self.device.schedule_field_current(body.at_sample_index, body.current_a)

    def _send(self, body: Body, stamp_ns: int) -> None:
        """Frame ``body`` and queue it. Every frame takes a sequence number, also one that is
        lost because the device is unplugged or the host does not read."""
        data = encode_frame(Frame(self._sequence, stamp_ns, body))
        self._sequence += 1
        if self._fds is None:
            return
        if len(self._output) + len(data) > OUTPUT_LIMIT_BYTES:
            self.dropped_frames += 1
            return
        self._output += data

    def _flush(self) -> None:
        while self._output and self._fds is not None:
            try:
                written = os.write(self._fds[0], self._output)
            except (BlockingIOError, OSError):
                return
            del self._output[:written]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m mows.device.serial.emulator", description=__doc__.splitlines()[0])
    parser.add_argument("--link", required=True, help="path of the symbolic link to the pty (what the host opens)")
    parser.add_argument("--scenario", default="paper_largest_spacing", help="shipped scenario name or YAML file")
    parser.add_argument("--cap-a", type=float, default=CurrentCap().limit_a, help="coil current cap, A")
    parser.add_argument("--watchdog-timeout-s", type=float, default=WATCHDOG_TIMEOUT_S)
    args = parser.parse_args(argv)
    try:  # a bad argument, scenario or link path: one line and exit status 2, as every mows command
        if not (math.isfinite(args.cap_a) and args.cap_a > 0.0):
            raise ValueError(f"--cap-a {args.cap_a} is out of range: a finite coil current > 0 A")
        device = SimulatedDevice(load_scenario(args.scenario))
        emulator = DeviceEmulator(device, args.link, CurrentCap(args.cap_a), args.watchdog_timeout_s).start()
    except (ValueError, OSError) as error:
        print(f"{parser.prog}: error: {' '.join(str(error).split())}", file=sys.stderr)
        return 2
    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    try:
        print(f"device emulator on {args.link}", flush=True)
        stop.wait()
    finally:
        emulator.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
