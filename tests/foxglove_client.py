"""A client of Foxglove's WebSocket protocol (github.com/foxglove/ws-protocol, docs/spec.md)
with the ``websockets`` package, on a thread and event loop of its own, as a viewer connects.

The protocol: the server's text frames are JSON (``serverInfo``, ``advertise`` with each
channel's id, topic, encoding, schema name and schema); the client sends ``subscribe`` with
its own subscription ids; the server's binary frames are opcode 0x01 (message data), then the
subscription id (uint32 LE), the log time (uint64 LE, ns) and the message's bytes.
foxglove-sdk's server names the protocol ``foxglove.sdk.v1`` (the same protocol as
``foxglove.websocket.v1``, renamed; foxglove/ros-foxglove-bridge#382) and refuses a handshake
offering only the older name (tests/viz/test_live.py); the Foxglove app offers both.
"""

import asyncio
import json
import struct
import threading
import time
from collections.abc import Callable, Iterable

import websockets

SUBPROTOCOL = "foxglove.sdk.v1"
OLD_SUBPROTOCOL = "foxglove.websocket.v1"
MESSAGE_DATA = 0x01


class FoxgloveClient:
    """Connects to ``ws://127.0.0.1:port`` (again while the server is not up yet), subscribes to
    ``topics`` (every channel advertised when None) and keeps what it receives: ``messages``, by
    topic, each (log time in ns, bytes). ``ended`` is set once the server closed the connection."""

    def __init__(self, port: int, topics: Iterable[str] | None = None):
        self.port = port
        self.topics = None if topics is None else frozenset(topics)
        self.channels: dict[int, dict] = {}
        self.messages: dict[str, list[tuple[int, bytes]]] = {}
        self.errors: list[BaseException] = []
        self.ended = threading.Event()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=lambda: asyncio.run(self._run()), daemon=True)
        self._thread.start()

    def payloads(self, topic: str) -> list[bytes]:
        return [data for _, data in self.messages.get(topic, [])]

    def channel(self, topic: str) -> dict:
        return next(c for c in self.channels.values() if c["topic"] == topic)

    def wait_for(self, condition: Callable[[], object], what: str, bound_s: float = 60.0):
        """``condition()``'s value once true; fails after ``bound_s`` or at the client's error."""
        deadline = time.monotonic() + bound_s
        while not (value := condition()):
            assert not self.errors, self.errors
            if time.monotonic() > deadline:
                raise AssertionError(f"gave up after {bound_s} s waiting for {what}")
            time.sleep(0.05)
        return value

    def close(self) -> None:
        self._stop.set()
        self._thread.join(10)

    async def _run(self) -> None:
        try:
            while not self._stop.is_set():
                try:
                    async with websockets.connect(f"ws://127.0.0.1:{self.port}", subprotocols=[SUBPROTOCOL]) as ws:
                        assert ws.subprotocol == SUBPROTOCOL
                        await self._talk(ws)
                        return
                except OSError:  # the server is not up yet
                    await asyncio.sleep(0.5)
        except websockets.ConnectionClosed:
            pass
        except BaseException as error:  # noqa: BLE001 (told to the test)
            self.errors.append(error)
        finally:
            self.ended.set()

    async def _talk(self, ws) -> None:
        subscribed: dict[int, str] = {}
        while not self._stop.is_set():
            try:
                frame = await asyncio.wait_for(ws.recv(), 0.5)
            except TimeoutError:
                continue
            if isinstance(frame, str):
                message = json.loads(frame)
                if message["op"] == "advertise":
                    wanted = []
                    for channel in message["channels"]:
                        self.channels[channel["id"]] = channel
                        if self.topics is None or channel["topic"] in self.topics:
                            subscription = len(subscribed) + 1
                            subscribed[subscription] = channel["topic"]
                            wanted.append({"id": subscription, "channelId": channel["id"]})
                    if wanted:
                        await ws.send(json.dumps({"op": "subscribe", "subscriptions": wanted}))
            elif frame[0] == MESSAGE_DATA:
                subscription, log_time = struct.unpack_from("<IQ", frame, 1)
                self.messages.setdefault(subscribed[subscription], []).append((log_time, frame[13:]))
