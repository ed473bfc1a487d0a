"""The live server's channels with a client that connects late: foxglove-sdk's WebSocket server
on a free port, a client speaking its protocol with the ``websockets`` package (opcode 0x01:
subscription id, log time, the message's bytes; tests/ros/test_viz_live.py), subscribing after
the sweep was shown."""

import asyncio
import json
import struct

import foxglove
import websockets

from foxglove_protobuf import decode, descriptors
from mows.viz import channels
from mows.viz.live import KEPT, LiveChannels
from mows.viz.view import RAW, SCENE, SWEEP, View
from viz.session import sweep_message

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 0x01


async def first_messages(port: int, seconds: float = 5.0) -> dict[str, list[tuple[int, bytes]]]:
    """What a client subscribing to every channel receives within ``seconds``, by topic."""
    received: dict[str, list[tuple[int, bytes]]] = {}
    topics: dict[int, str] = {}
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL]) as ws:
        loop = asyncio.get_running_loop()
        end = loop.time() + seconds
        while (left := end - loop.time()) > 0:
            try:
                frame = await asyncio.wait_for(ws.recv(), left)
            except TimeoutError:
                break
            if isinstance(frame, str):
                message = json.loads(frame)
                if message["op"] == "advertise":
                    wanted = []
                    for channel in message["channels"]:
                        topics[channel["id"]] = channel["topic"]
                        wanted.append({"id": channel["id"], "channelId": channel["id"]})
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": wanted}))
            elif frame[0] == MESSAGE_DATA:
                subscription, log_time = struct.unpack_from("<IQ", frame, 1)
                received.setdefault(topics[subscription], []).append((log_time, frame[13:]))
    return received


def test_a_client_connecting_after_a_sweep_sees_its_scene_and_sweep_at_once():
    view, live = View(), LiveChannels()
    server = foxglove.start_server(name="mows-test", port=0, server_listener=live)
    try:
        older, newer = sweep_message(1.0), sweep_message(2.0)
        newer.sweep_id = 2
        for time_ns, msg in ((1_000_000_000, older), (2_000_000_000, newer)):
            for shown in view.on_sweep(msg, time_ns):
                live.log(shown)
        received = asyncio.run(first_messages(server.port))
    finally:
        server.stop()
        live.close()
    # The latest of each kept channel shown so far, once, and nothing of the channels not shown.
    assert set(received) == {SCENE, SWEEP}
    ((sweep_time, sweep),), ((scene_time, scene),) = received[SWEEP], received[SCENE]
    assert (sweep_time, json.loads(sweep)["sweep_id"]) == (2_000_000_000, 2)
    found = channels.schema(SCENE)
    update = decode(scene, found.name, descriptors(found.data))
    assert scene_time == 2_000_000_000 and update["entities"][0]["arrows"]


def test_every_channel_but_the_raw_stream_is_kept():
    assert set(KEPT) == set(channels.TOPICS) - {RAW}
