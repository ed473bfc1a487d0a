"""The live server's channels with a client that connects late: foxglove-sdk's WebSocket server
on a free port, a client speaking its protocol (tests/foxglove_client.py), subscribing after the
sweep was shown; and the protocol's names that server accepts."""

import asyncio
import json

import foxglove
import pytest
import websockets

from foxglove_client import OLD_SUBPROTOCOL, SUBPROTOCOL, FoxgloveClient
from foxglove_protobuf import decode, descriptors
from mows.viz import channels
from mows.viz.live import KEPT, LiveChannels
from mows.viz.view import RAW, SCENE, SWEEP, View
from viz.session import sweep_message


def test_a_client_connecting_after_a_sweep_sees_its_scene_and_sweep_at_once():
    view, live = View(), LiveChannels()
    server = foxglove.start_server(name="mows-test", port=0, server_listener=live)
    try:
        older, newer = sweep_message(1.0), sweep_message(2.0)
        newer.sweep_id = 2
        for time_ns, msg in ((1_000_000_000, older), (2_000_000_000, newer)):
            for shown in view.on_sweep(msg, time_ns):
                live.log(shown)
        client = FoxgloveClient(server.port)
        try:
            client.wait_for(lambda: SCENE in client.messages and SWEEP in client.messages, "the scene and the sweep")
            client.wait_for(lambda: len(client.channels) == len(channels.TOPICS), "every channel advertised")
        finally:
            client.close()
    finally:
        server.stop()
        live.close()
    # The latest of each kept channel shown so far, once, and nothing of the channels not shown.
    received = client.messages
    assert set(received) == {SCENE, SWEEP}
    ((sweep_time, sweep),), ((scene_time, scene),) = received[SWEEP], received[SCENE]
    assert (sweep_time, json.loads(sweep)["sweep_id"]) == (2_000_000_000, 2)
    found = channels.schema(SCENE)
    update = decode(scene, found.name, descriptors(found.data))
    assert scene_time == 2_000_000_000 and update["entities"][0]["arrows"]


def test_every_channel_but_the_raw_stream_is_kept():
    assert set(KEPT) == set(channels.TOPICS) - {RAW}


def test_the_server_speaks_foxglove_sdk_v1_and_refuses_the_older_name_alone():
    # foxglove-sdk has no setting for the subprotocols it accepts (docs/visualisation.md): a
    # viewer that offers only foxglove.websocket.v1 cannot connect, one that offers both can.
    async def handshake(offered: list[str]) -> str:
        async with websockets.connect(f"ws://127.0.0.1:{server.port}", subprotocols=offered) as ws:
            return ws.subprotocol

    server = foxglove.start_server(name="mows-test", port=0)
    try:
        assert asyncio.run(handshake([OLD_SUBPROTOCOL, SUBPROTOCOL])) == SUBPROTOCOL
        with pytest.raises(websockets.InvalidStatus, match="HTTP 400"):
            asyncio.run(handshake([OLD_SUBPROTOCOL]))
    finally:
        server.stop()
