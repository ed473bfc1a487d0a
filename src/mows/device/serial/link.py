"""The host's end of the serial link (docs/serial_protocol.md), with reconnection.

A reader thread keeps the port open: it opens it, sends Hello, and counts the link as up
once the device answers with DeviceInfo; it reads and decodes frames as they come (so that
the OS buffers never overflow while the driver is busy) and queues them. When the port fails
(the cable is pulled) it reports the link down, counts the frame cut short, and tries to open
the port again after a delay that doubles from ``backoff_initial_s`` up to ``backoff_max_s``
and starts over once the device is back.

Heartbeats are sent from :meth:`SerialLink.poll`, the driver's own loop, not from the reader
thread: if the driver stops polling (it hangs), the heartbeats stop and the device's
watchdog switches the coils off.
"""

from __future__ import annotations

import queue
import threading
import time

import serial

from mows.device.interface import LinkEvent, NotExciting
from mows.device.protocol.framing import SEQUENCE_MODULUS, Frame, FrameDecoder, encode_frame
from mows.device.protocol.payloads import Body, DeviceInfo, Heartbeat, Hello

DEFAULT_BAUD = 2_000_000  # 20 kS/s × 2 channels × 4 bytes + framing ≈ 170 kB/s
HEARTBEAT_PERIOD_S = 0.05  # a third of the device's 150 ms watchdog
BACKOFF_INITIAL_S = 0.05
BACKOFF_MAX_S = 2.0
HELLO_TIMEOUT_S = 1.0  # a port with no device answering Hello is treated as lost
READ_TIMEOUT_S = 0.05


class SerialLink:
    """Frames to and from the device on serial port ``port``."""

    def __init__(
        self,
        port: str,
        baud: int = DEFAULT_BAUD,
        heartbeat_period_s: float = HEARTBEAT_PERIOD_S,
        backoff_initial_s: float = BACKOFF_INITIAL_S,
        backoff_max_s: float = BACKOFF_MAX_S,
        hello_timeout_s: float = HELLO_TIMEOUT_S,
    ):
        self.port, self.baud = port, baud
        self.heartbeat_period_s = heartbeat_period_s
        self.backoff_initial_s, self.backoff_max_s = backoff_initial_s, backoff_max_s
        self.hello_timeout_s = hello_timeout_s
        self.info: DeviceInfo | None = None  # the device's description, once it has answered
        self.up = False
        self.decoder = FrameDecoder()
        self.lost_frames = 0  # frames the device numbered after the first connection but we never received
        self.sequence_restarts = 0  # the device's frame counter went back (it rebooted)
        self.connections = 0  # times the link came up
        self.open_failures = 0
        self.retry_delays_s: list[float] = []  # the back-off before each new attempt to open
        self.last_error = ""
        self._serial: serial.Serial | None = None
        self._expected_sequence: int | None = None
        self._sequence = 0
        self._last_sent_s = 0.0
        self._hello_deadline_s: float | None = None
        self._frames: queue.SimpleQueue = queue.SimpleQueue()
        self._write_lock = threading.Lock()
        self._stopping = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"mows-serial {port}", daemon=True)

    def start(self) -> SerialLink:
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop the reader (its reads time out within READ_TIMEOUT_S), then close the port."""
        self._stopping.set()
        if self._thread.is_alive():
            self._thread.join()
        self._drop("closed")

    # --- the driver's side -----------------------------------------------------------------
    def poll(self, timeout_s: float) -> list:
        """Frames and LinkEvents received since the last poll, waiting up to ``timeout_s`` for
        the first. Sends a heartbeat when one is due."""
        if self.up and time.monotonic() - self._last_sent_s >= self.heartbeat_period_s:
            try:
                self.send(Heartbeat())
            except NotExciting:
                pass  # the link just went down: the reader reports it
        items = []
        try:
            items.append(self._frames.get(timeout=timeout_s))
            while True:
                items.append(self._frames.get_nowait())
        except queue.Empty:
            return items

    def send(self, body: Body) -> int:
        """Send ``body``; its sequence number. NotExciting when the link is down."""
        if not self.up:
            raise NotExciting(f"the link to the device on {self.port} is down ({self.last_error})")
        return self._write(body)

    def _write(self, body: Body) -> int:
        with self._write_lock:
            if self._serial is None:
                raise NotExciting(f"the port {self.port} is not open ({self.last_error})")
            sequence = self._sequence
            try:
                self._serial.write(encode_frame(Frame(sequence, time.monotonic_ns(), body)))
            except (serial.SerialException, OSError) as error:
                raise NotExciting(f"writing to {self.port} failed: {error}") from None
            self._sequence = (sequence + 1) % SEQUENCE_MODULUS
            self._last_sent_s = time.monotonic()
            return sequence

    def stats(self) -> dict:
        return {
            "link": "up" if self.up else "down",
            "port": self.port,
            "connections": self.connections,
            "open_failures": self.open_failures,
            "lost_frames": self.lost_frames,
            "sequence_restarts": self.sequence_restarts,
            "rejected_frames": self.decoder.rejected_total,
            **{f"rejected_{reason}": n for reason, n in sorted(self.decoder.rejected.items())},
            "last_error": self.last_error,
        }

    # --- the reader thread -----------------------------------------------------------------
    def _run(self) -> None:
        delay = self.backoff_initial_s
        while not self._stopping.is_set():
            if self._serial is None:
                if not self._open():
                    self.retry_delays_s.append(delay)
                    self._stopping.wait(delay)
                    delay = min(2.0 * delay, self.backoff_max_s)
                    continue
                delay = self.backoff_initial_s
            self._read()

    def _open(self) -> bool:
        try:
            port = serial.Serial(
                self.port, self.baud, timeout=READ_TIMEOUT_S, write_timeout=READ_TIMEOUT_S, exclusive=True
            )
        except (serial.SerialException, OSError, ValueError) as error:
            self.open_failures += 1
            self._never_connected(f"cannot open {self.port}: {error}")
            return False
        with self._write_lock:
            self._serial = port
        self._hello_deadline_s = time.monotonic() + self.hello_timeout_s
        try:
            self._write(Hello())
        except NotExciting as error:
            self._drop(str(error))
        return True

    def _read(self) -> None:
        port = self._serial
        try:
            data = port.read(max(1, port.in_waiting))  # type: ignore[union-attr]  # None: AttributeError below
        except (serial.SerialException, OSError, TypeError, AttributeError) as error:
            # TypeError/AttributeError: pyserial's read on a port closed under it by close().
            self._drop(f"reading {self.port} failed: {error}")
            return
        for frame in self.decoder.feed(data):
            self._received(frame)
        if self._hello_deadline_s is not None and time.monotonic() > self._hello_deadline_s:
            self._drop(f"no device answered on {self.port} within {self.hello_timeout_s:g} s")

    def _received(self, frame: Frame) -> None:
        # Frames count as lost only once a link was established: what the device numbered
        # before it first answered Hello (it streams from power-on) was never the link's to lose.
        if self.connections and self._expected_sequence is not None:
            jump = (frame.sequence - self._expected_sequence) % SEQUENCE_MODULUS
            if jump >= SEQUENCE_MODULUS // 2:
                self.sequence_restarts += 1
            else:
                self.lost_frames += jump
        self._expected_sequence = (frame.sequence + 1) % SEQUENCE_MODULUS
        if isinstance(frame.body, DeviceInfo):
            self.info = frame.body
            self._hello_deadline_s = None
            if not self.up:
                self.up = True
                self.connections += 1
                self.last_error = ""  # the link is back: an old failure is no longer the state
                self._frames.put(LinkEvent(True, f"device answered on {self.port}"))
        self._frames.put(frame)

    def _drop(self, reason: str) -> None:
        """Close the port; frames cut short are counted, and the link is reported down."""
        with self._write_lock:
            port, self._serial = self._serial, None
        if port is None:
            return
        port.close()
        self._never_connected(reason)
        self.last_error = reason
        for frame in self.decoder.finish():
            self._received(frame)
        self._hello_deadline_s = None
        if self.up:
            self.up = False
            self._frames.put(LinkEvent(False, reason))

    def _never_connected(self, reason: str) -> None:
        """Until a device first answers, each new reason it does not is reported as the link
        down (a port that does not exist, a file that is no terminal, a silent device): the
        driver says why it streams nothing, once per reason, not once per retry."""
        if self.connections == 0 and reason != self.last_error:
            self._frames.put(LinkEvent(False, reason))
        self.last_error = reason
