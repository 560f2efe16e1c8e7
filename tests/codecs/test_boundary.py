"""The codec boundary carries text: any str round-trips through every registered codec,
and raw_size is the UTF-8 size of the canonical framing (the on-disk raw_len)."""

import json
import struct
import threading

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.codecs import codec_for_record, codec_from_config, frame, raw_size, registered_ids, utf8_size
from cclogfs.errors import CodecError

# Any text UTF-8 can encode (Hypothesis leaves out surrogates), JSON-shaped or not, so
# the columnar codec sees both texts it can shape and texts it stores verbatim.
texts = st.text(max_size=30) | st.builds(json.dumps, st.dictionaries(st.text(max_size=4), st.text(max_size=6)),
                                         ensure_ascii=st.booleans())  # fmt: skip
windows = st.lists(texts, max_size=12)


@settings(max_examples=60, deadline=None)
@given(windows, st.sampled_from(registered_ids()))
def test_any_text_round_trips_through_every_codec(window, codec_id):
    codec = codec_from_config(codec_id)
    stamps = list(range(len(window)))
    data = codec.encode(stamps, window)
    assert codec.decode(data, count=len(window), raw_len=raw_size(stamps, window)) == (stamps, window)


@given(windows)
def test_raw_size_is_the_utf8_framing_length(window):
    stamps = [0] * len(window)
    data = [t.encode("utf-8") for t in window]
    expected = struct.pack(f"<I{len(data)}q{len(data)}I", len(data), *stamps, *map(len, data)) + b"".join(data)
    assert raw_size(stamps, window) == len(frame(stamps, window)) == len(expected)
    assert frame(stamps, window) == expected
    assert utf8_size(window) == sum(map(len, data))


def test_a_lone_surrogate_is_a_codec_error_not_a_crash():
    for codec_id in registered_ids():
        with pytest.raises(CodecError, match="UTF-8 cannot encode"):
            codec_from_config(codec_id).encode([0], ['"\ud800"'])


def test_stray_bytes_come_back_as_surrogate_escapes():
    """A payload may hold bytes that are not UTF-8 (the store never writes them): they
    decode to surrogate escapes, which encode back to the same bytes."""
    raw = b"\xff not utf-8"
    payload = struct.pack("<IqI", 1, 5, len(raw)) + raw
    stamps, got = codec_from_config("none").decode(payload, count=1, raw_len=len(payload))
    assert got[0].encode("utf-8", "surrogateescape") == raw


def test_read_codecs_are_built_once_per_config_and_shared_by_threads():
    config = b'{"id":"zstd","level":3}'
    codec = codec_for_record(config)
    assert codec_for_record(config) is codec and codec.get_config() == {"id": "zstd", "level": 3}
    window = [json.dumps({"i": i, "s": "é" * (i % 5)}) for i in range(200)]
    stamps = list(range(200))
    data = codec.encode(stamps, window)
    results, errors = [], []

    def read():  # each thread gets its own zstd context inside the shared codec
        try:
            for _ in range(50):
                results.append(codec.decode(data, count=200, raw_len=raw_size(stamps, window)) == (stamps, window))
        except Exception as err:  # noqa: BLE001 - reported below
            errors.append(err)

    threads = [threading.Thread(target=read) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors and len(results) == 200 and all(results)
