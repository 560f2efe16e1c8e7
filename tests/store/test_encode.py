"""cclogfs.store.encode: a window checked and encoded into a record, the same for a put and a
compaction replacement."""

import json
import math

import pytest

from cclogfs.codecs import codec_from_config, codec_numeric_id
from cclogfs.errors import InvalidInputError
from cclogfs.store.encode import Codecs, encode_meta, encode_window
from cclogfs.store.format import MAX_CONFIG, MAX_META, RECORD_FIXED_SIZE, check_fixed, check_payload, parse_header

MESSAGES = [(10, '{"a":1}'), (20, '{"a":2}'), (35, '{"a":3}')]


def codecs(**per_stream):
    return Codecs(codec_from_config("columnar"), {k: codec_from_config(v) for k, v in per_stream.items()})


def test_encode_meta_is_compact_json():
    assert encode_meta({"b": [1, 2], "a": "x"}) == b'{"b":[1,2],"a":"x"}'
    assert encode_meta({}) == b"{}"


@pytest.mark.parametrize(
    "meta, message",
    [
        (["not", "a", "dict"], "meta must be a dict, got list"),
        ({"f": object()}, "not JSON-serializable"),
        ({"x": math.nan}, "not JSON-serializable"),
        ({"big": "x" * MAX_META}, f"over the {MAX_META}-byte limit"),
    ],
)
def test_encode_meta_rejects_bad_meta_with_one_line(meta, message):
    with pytest.raises(InvalidInputError, match=message) as err:
        encode_meta(meta)
    assert "\n" not in str(err.value)


def test_encode_window_packs_a_record_that_reads_back():
    enc = encode_window(codecs(), "/odom", MESSAGES, {"k": 1}, None, check_json=True)
    assert (enc.name, enc.stamps, enc.meta) == (b"/odom", [10, 20, 35], b'{"k":1}')
    data = enc.pack(seq=7, flags=0)
    header_len = check_fixed(data[:RECORD_FIXED_SIZE], len(data))
    header = parse_header(data[:header_len])
    check_payload(header, data[header_len:])  # raises when the payload hash does not match
    assert (header.seq, header.start_ns, header.end_ns, header.count) == (7, 10, 35, 3)
    assert (header.name, header.meta, header.raw_len) == ("/odom", b'{"k":1}', enc.raw_len)
    assert json.loads(header.config)["id"] == "columnar"
    assert len(data) == header.record_len


def test_no_meta_is_an_empty_object():
    assert encode_window(codecs(), "/a", MESSAGES, None, None, check_json=True).meta == b"{}"


def test_codec_choice_call_then_stream_then_default():
    c = codecs(**{"/raw": "zstd"})
    assert c.for_stream("/odom") is c.default
    assert c.for_stream("/raw") is c.per_stream["/raw"]
    assert c.for_stream("/odom", "zstd").codec_id == "zstd"
    enc = encode_window(c, "/raw", MESSAGES, None, None, check_json=True)
    assert enc.codec == codec_numeric_id(c.per_stream["/raw"])
    assert enc.codec != encode_window(c, "/odom", MESSAGES, None, None, check_json=True).codec


def test_header_is_cached_for_the_stores_codecs_only():
    c = codecs()
    config, number = c.header(c.default)
    assert json.loads(config) == c.default.get_config() and number == codec_numeric_id(c.default)
    assert c.header(c.default) == (config, number) and id(c.default) in c._headers
    one_off = codec_from_config("zstd")
    c.header(one_off)
    assert id(one_off) not in c._headers  # a per-call codec is not kept alive by the cache


@pytest.mark.parametrize(
    "name, messages, check_json, message",
    [
        ("", MESSAGES, True, "stream name"),
        ("/a", [], True, "needs at least one message"),
        ("/a", [(20, "{}"), (10, "{}")], True, "message 1: stamp_ns 10 is before"),
        ("/a", [(10, "{not json")], True, "message 0 is not well-formed JSON"),
    ],
)
def test_encode_window_rejects_bad_windows(name, messages, check_json, message):
    with pytest.raises(InvalidInputError, match=message):
        encode_window(codecs(), name, messages, None, None, check_json=check_json)


def test_unchecked_json_is_stored_as_given():
    enc = encode_window(codecs(), "/a", [(1, "{not json")], None, None, check_json=False)
    assert enc.stamps == [1]


def test_a_codec_config_over_the_limit_is_refused():
    class Huge:
        codec_id = "columnar"

        def get_config(self):
            return {"id": "columnar", "pad": "x" * MAX_CONFIG}

    c = codecs()
    with pytest.raises(InvalidInputError, match=f"over {MAX_CONFIG}"):
        c.header(Huge())
