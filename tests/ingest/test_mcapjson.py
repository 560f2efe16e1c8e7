"""cclogfs.ingest.mcapjson: MCAP files whose channels carry JSON messages."""

from __future__ import annotations

import pytest
from mcap.writer import Writer

from cclogfs.errors import SourceError
from cclogfs.ingest import McapJsonSource, detect_format, open_source
from cclogfs.ingest.mcapjson import mcap_encodings


def _write_json_mcap(path, rows, encoding="json"):
    with open(path, "wb") as f:
        w = Writer(f)
        w.start()
        schema = w.register_schema("demo/Thing", "jsonschema", b'{"type": "object"}')
        chans = {}
        for topic, t, text in rows:
            if topic not in chans:
                chans[topic] = w.register_channel(topic, encoding, schema)
            w.add_message(chans[topic], log_time=t, data=text.encode(), publish_time=t)
        w.finish()


def test_plain_json_mcap(tmp_path):
    rows = [("/a", 5, '{"x": 1.5}'), ("/b", 7, '{"y":  [1,2]}'), ("/a", 9, '{"x": NaN}')]
    path = tmp_path / "plain.mcap"
    _write_json_mcap(path, rows)
    assert detect_format(path) == "mcap-json"
    with open_source(path) as src:
        assert isinstance(src, McapJsonSource)
        assert src.topics() == {"/a": "demo/Thing", "/b": "demo/Thing"}
        assert [(m.topic, m.stamp_ns, m.text) for m in src] == rows
    with open_source(path, topics=["/b"]) as src:
        assert [m.text for m in src] == ['{"y":  [1,2]}']


def test_json_mcap_with_broken_message(tmp_path):
    path = tmp_path / "bad.mcap"
    _write_json_mcap(path, [("/a", 5, '{"x": 1'), ("/a", 6, "{}")])
    with open_source(path) as src, pytest.raises(SourceError, match=r"bad.mcap.*/a.*5 ns.*JSON"):
        list(src)


def test_mcap_with_other_encoding_is_refused(tmp_path):
    path = tmp_path / "proto.mcap"
    _write_json_mcap(path, [("/a", 5, "xx")], encoding="protobuf")
    with pytest.raises(SourceError, match=r"proto.mcap.*\['protobuf'\]"):
        open_source(path)


def test_mcap_encodings_lists_every_channel_encoding(tmp_path):
    path = tmp_path / "two.mcap"
    _write_json_mcap(path, [("/a", 5, "{}")])
    assert mcap_encodings(path) == {"json"}
    with pytest.raises(SourceError, match=r"Cannot read .*missing.mcap"):
        mcap_encodings(tmp_path / "missing.mcap")
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap at all")
    with pytest.raises(SourceError, match=r"junk.mcap is not a readable MCAP file"):
        mcap_encodings(tmp_path / "junk.mcap")
