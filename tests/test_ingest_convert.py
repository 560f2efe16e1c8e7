"""The cached converter writes exactly what rosjson writes, on every real message."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from cclogfs.ingest.convert import MessageConverter
from cclogfs.rosjson import message_to_json


@pytest.mark.parametrize("name", ["nav2_turtlebot.mcap", "tf_example.bag", "tf_example"])
def test_same_text_as_rosjson(shared_data, name):
    conv = MessageConverter()
    with AnyReader([shared_data(name)]) as reader:
        n = 0
        for con, _, raw in reader.messages():
            msg = reader.deserialize(raw, con.msgtype)
            assert conv.to_json(msg) == message_to_json(msg)
            n += 1
    assert n > 500


@dataclasses.dataclass
class Leaf:
    data: np.ndarray
    raw: bytes
    scalar: np.float32
    items: list
    __msgtype__: str = "demo/msg/Leaf"


def test_same_text_for_arrays_bytes_and_numpy_scalars():
    msg = Leaf(
        data=np.array([1, 2, 255], dtype=np.uint8),
        raw=b"\x00\x01",
        scalar=np.float32(0.5),
        items=[Leaf(np.array([1.5, np.nan]), bytearray(b"z"), np.int64(3), [])],
    )
    assert MessageConverter().to_json(msg) == message_to_json(msg)
    assert '"data": "AQL/"' in message_to_json(msg)
