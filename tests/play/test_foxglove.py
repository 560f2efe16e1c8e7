"""`cclog play --foxglove`: a WebSocket client speaking the Foxglove protocol subscribes to
every channel and receives every stored message, with the ROS type as the schema name."""

from __future__ import annotations

import json
import re
import struct
import subprocess
import sys

import pytest

from cclogfs import open_store
from cclogfs.runs import hidden_by_default

CCLOG = [sys.executable, "-m", "cclogfs"]
websockets_sync = pytest.importorskip("websockets.sync.client")


def serve(store, *args):
    proc = subprocess.Popen([*CCLOG, "play", str(store), "--foxglove", "0", "--wait-for-subscribers", *args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)  # fmt: skip
    line = proc.stderr.readline()
    m = re.search(r"ws://127\.0\.0\.1:(\d+)", line)
    assert m, line + proc.stderr.read()
    return proc, int(m.group(1))


def receive_all(port, expected):
    """Connect, subscribe to every advertised channel, collect (topic, log_time, text)."""
    got, channels = [], {}
    with websockets_sync.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                                 open_timeout=20) as ws:  # fmt: skip
        while len(got) < expected:
            frame = ws.recv(timeout=30)
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] == "advertise":
                    subs = []
                    for ch in msg["channels"]:
                        channels[ch["id"]] = ch
                        subs.append({"id": ch["id"], "channelId": ch["id"]})
                    ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
            elif frame[0] == 1:  # message data: subscription id, log time, payload
                sub, log_time = struct.unpack_from("<IQ", frame, 1)
                got.append((channels[sub]["topic"], log_time, frame[13:].decode()))
    return got, channels


def test_foxglove_client_receives_every_message_with_its_type(shared_data, tmp_path):
    subprocess.run([*CCLOG, "record", str(shared_data("tf_example.bag")), "--store", str(tmp_path / "s")],
                   check=True, capture_output=True)  # fmt: skip
    with open_store(tmp_path / "s", readonly=True) as store:
        want = sorted((w.name, s, t) for w in store.query() if not hidden_by_default(w.name) for s, t in w.messages())
    proc, port = serve(tmp_path / "s", "--rate", "50")
    try:
        got, channels = receive_all(port, len(want))
        assert proc.wait(timeout=60) == 0
    finally:
        proc.kill()
    assert sorted(got) == want and len(want) == 518
    assert {c["topic"]: c["schemaName"] for c in channels.values()} == {
        "/tf": "tf2_msgs/msg/TFMessage", "/tf_static": "tf2_msgs/msg/TFMessage"}
    assert {c["encoding"] for c in channels.values()} == {"json"}
    assert json.loads(next(iter(channels.values()))["schema"])["type"] == "object"
