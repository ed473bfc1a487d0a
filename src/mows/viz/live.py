"""The live server's channels: each of :data:`mows.viz.channels.TOPICS` on foxglove-sdk's
WebSocket server, and each channel's last message re-sent to a client that subscribes to it,
so that a client connecting after a sweep sees its scene, sweep, lab history and excitation
at once instead of at the next one. The raw stream is not kept: it is a stream, its next
samples come within a block.

foxglove-sdk sends a message logged from the subscribe callback to that subscription (and to
the channel's other subscribers, which see the same latest message again: the panels that show
the latest message are unchanged by it).
"""

from __future__ import annotations

import threading

import foxglove
from foxglove.websocket import ChannelView, Client, ServerListener

from mows.viz import channels
from mows.viz import view as v

KEPT = tuple(topic for topic in channels.TOPICS if topic != v.RAW)


class LiveChannels(ServerListener):
    """The channels, advertised from the start so that a client sees them all before data come."""

    def __init__(self) -> None:
        self._channels: dict[str, foxglove.Channel] = {}
        for topic in channels.TOPICS:
            found = channels.schema(topic)
            self._channels[topic] = foxglove.Channel(
                topic,
                schema=foxglove.Schema(name=found.name, encoding=found.encoding, data=found.data),
                message_encoding=found.message_encoding,
            )
        self._last: dict[str, tuple[bytes, int]] = {}
        self._lock = threading.Lock()

    def log(self, shown: v.Shown) -> None:
        data, time_ns = channels.payload(shown), int(shown.log_time_ns)
        if shown.topic in KEPT:
            with self._lock:  # kept before it is sent: a subscriber it misses gets it re-sent
                self._last[shown.topic] = (data, time_ns)
        # Never sent under the lock: the server may hold its own while it calls on_subscribe.
        self._channels[shown.topic].log(data, log_time=time_ns)

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        sent = None
        while True:
            with self._lock:
                last = self._last.get(channel.topic)
            # A message kept while the older one was re-sent would end behind it: send it too.
            if last is None or last is sent:
                return
            self._channels[channel.topic].log(last[0], log_time=last[1])
            sent = last

    def close(self) -> None:
        for channel in self._channels.values():
            channel.close()
        self._channels.clear()
