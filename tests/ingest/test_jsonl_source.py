"""JSON Lines source: byte-exact message text, both parse paths, malformed lines; every
test once with the compiled splitter and once without (the split_path fixture)."""

from __future__ import annotations

import io
import json
import sys

import pytest

from cclogfs.errors import InvalidInputError, SourceError
from cclogfs.ingest import JsonlSource, detect_format, format_line, open_source, parse_line

pytestmark = pytest.mark.usefixtures("split_path")

ODOM = '{"header": {"stamp": {"sec": 1, "nanosec": 5}, "frame_id": "odom"}, "v": [1.0, -0.0, NaN]}'


def write(tmp_path, text, name="log.jsonl"):
    path = tmp_path / name
    path.write_bytes(text.encode("utf-8"))
    return path


def test_canonical_line_round_trip():
    line = format_line("/odom", 1432235695834049087, ODOM)
    assert line == f'{{"topic": "/odom", "stamp_ns": 1432235695834049087, "msg": {ODOM}}}\n'
    assert parse_line(line[:-1]) == ("/odom", 1432235695834049087, ODOM, "")
    typed = format_line("/odom", 3, ODOM, msgtype="nav_msgs/msg/Odometry")
    assert parse_line(typed[:-1]) == ("/odom", 3, ODOM, "nav_msgs/msg/Odometry")


@pytest.mark.parametrize(
    "line",
    [
        # other key orders, spacing, escapes: all keep the msg text exactly
        '{"msg": %s, "stamp_ns": 7, "topic": "/odom"}',
        '  { "topic" : "/odom" ,"stamp_ns":7,"msg" :%s }  ',
        '{"topic": "\\/odom", "stamp_ns": 7, "msg": %s}',
        '{"topic": "/odom", "stamp_ns": 7, "msg": %s, "msgtype": ""}',
    ],
)
def test_other_layouts_keep_msg_bytes(line):
    msg = '{ "a" :1.50,"b":[ 1 ,2],"s":"\\u00e9\\n", "t": "é"}'
    assert parse_line(line % msg) == ("/odom", 7, msg, "")


def test_file_source_is_byte_exact(tmp_path):
    texts = [ODOM, '{"x":1}', '{"x": 1e400, "y": "\\"}\\""}', "{}"]
    body = "".join(format_line(f"/t{i % 2}", i, t) for i, t in enumerate(texts))
    path = write(tmp_path, body)
    assert detect_format(path) == "jsonl"
    with open_source(path) as src:
        got = list(src)
    assert [(m.topic, m.stamp_ns, m.text) for m in got] == [
        (f"/t{i % 2}", i, t) for i, t in enumerate(texts)
    ]
    with open_source(path, topics=["/t1"]) as src:
        assert [m.text for m in src] == [texts[1], texts[3]]


def test_crlf_blank_lines_and_no_final_newline(tmp_path):
    path = write(tmp_path, format_line("/a", 1, "{}").replace("\n", "\r\n") + "\n  \n"
                 + format_line("/a", 2, '{"k": 2}')[:-1])
    with JsonlSource(path) as src:
        assert [(m.stamp_ns, m.text) for m in src] == [(1, "{}"), (2, '{"k": 2}')]


BAD_LINES = [
    ('{"topic": "/a", "stamp_ns": 1, "msg": {"x": 1}', r"line 2: invalid JSON: Expecting"),
    ('{"topic": "/a", "stamp_ns": 1, "msg": {"x": 1}} extra', r"line 2: invalid JSON: Extra data"),
    ('[1, 2]', r"line 2: a line must hold one JSON object"),
    ('{"topic": "/a", "msg": {}}', r"line 2: the object has no 'stamp_ns' key"),
    ('{"topic": "/a", "stamp_ns": 1.5, "msg": {}}', r"line 2: 'stamp_ns' must be a 64-bit integer"),
    ('{"topic": "/a", "stamp_ns": -9223372036854775809, "msg": {}}', r"line 2: 'stamp_ns' must be a 64-bit integer"),
    ('{"topic": "/a", "stamp_ns": 9223372036854775808, "msg": {}}', r"line 2: 'stamp_ns' must"),
    ('{"topic": "", "stamp_ns": 1, "msg": {}}', r"line 2: 'topic' must be a non-empty string"),
    ('{"topic": "/a", "stamp_ns": 1, "msg": [1]}', r"line 2: 'msg' must be a JSON object"),
    ('{"topic": "/a", "stamp_ns": 1, "msg": {}, "msg": {}}', r"line 2: duplicate key 'msg'"),
    ('{"topic": "/a", "stamp_ns": 1, "msg": {}, "extra": 3}', r"line 2: unknown key 'extra'"),
]


@pytest.mark.parametrize("bad, reason", BAD_LINES)
def test_malformed_line_stops_with_file_and_line(tmp_path, bad, reason):
    path = write(tmp_path, format_line("/a", 0, "{}") + bad + "\n" + format_line("/a", 2, "{}"))
    with JsonlSource(path) as src:
        with pytest.raises(SourceError, match=rf"log.jsonl, {reason}"):
            list(src)


def test_malformed_lines_skipped_and_reported(tmp_path):
    lines = [format_line("/a", 0, "{}")] + [b + "\n" for b, _ in BAD_LINES] + [format_line("/a", 9, "{}")]
    path = write(tmp_path, "".join(lines))
    seen = []
    with open_source(path, on_error="skip", report=seen.append) as src:
        assert [m.stamp_ns for m in src] == [0, 9]
    assert src.skipped == len(BAD_LINES) == len(seen)
    assert [str(e).split(",")[1].split(":")[0] for e in seen] == [
        f" line {n}" for n in range(2, 2 + len(BAD_LINES))
    ]


def test_a_topic_not_wanted_is_skipped_unchecked_in_the_canonical_layout(tmp_path):
    """As before the bytes fast path: a broken message of a topic not read is no error."""
    path = write(tmp_path, format_line("/a", 0, "{}") + '{"topic": "/b", "stamp_ns": 1, "msg": {"x": }}\n'
                 + format_line("/a", 2, '{"x": NaN}') + format_line("/b", 3, '{"x": 1}'))  # fmt: skip
    with JsonlSource(path, topics=["/a"]) as src:
        assert [(m.stamp_ns, m.text) for m in src] == [(0, "{}"), (2, '{"x": NaN}')]
    with JsonlSource(path) as src, pytest.raises(SourceError, match="line 2: invalid JSON"):
        list(src)


def test_invalid_utf8_is_a_line_error(tmp_path):
    path = tmp_path / "bin.jsonl"
    path.write_bytes(format_line("/a", 0, "{}").encode() + b'{"topic": "/\xff"}\n')
    with pytest.raises(SourceError, match=r"bin.jsonl, line 2: not UTF-8 text"):
        list(JsonlSource(path))


def test_stdin_source(monkeypatch):
    data = format_line("/a", 1, ODOM) + "oops\n"
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data.encode())))
    with open_source("-", on_error="skip") as src:
        assert [m.text for m in src] == [ODOM]
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data.encode())))
    with pytest.raises(SourceError, match=r"<stdin>, line 2: invalid JSON"):
        list(open_source("-"))


def test_format_line_refuses_line_breaks_and_bad_options(tmp_path):
    with pytest.raises(InvalidInputError, match=r"/a at 5 ns contains a line break"):
        format_line("/a", 5, '{\n"x": 1}')
    with pytest.raises(InvalidInputError, match=r"on_error must be"):
        JsonlSource(write(tmp_path, ""), on_error="ignore")
    with pytest.raises(InvalidInputError, match=r"topic selection is empty"):
        JsonlSource(write(tmp_path, ""), topics=[])


def test_msg_values_survive_json_round_trip(tmp_path):
    # What the fast path slices is exactly the msg value json.loads sees.
    texts = ['{"a": 1}', '{"a": "}\\"{"}', '{"nested": {"msg": {"x": [{}]}}}', '{"f": -1.5e-07}']
    path = write(tmp_path, "".join(format_line("/x", i, t) for i, t in enumerate(texts)))
    for line, msg in zip(path.read_text().splitlines(), JsonlSource(path)):
        assert json.loads(msg.text) == json.loads(line)["msg"]
        assert msg.text == texts[msg.stamp_ns]


def test_a_message_over_the_text_limit_is_a_line_error(tmp_path):
    # A record holds at most MAX_MESSAGE_TEXT bytes of one message; recording a longer one
    # used to fail in the store, naming "message 2 for '/a'" and no line (issue 16).
    big = '{"data": "%s"}' % ("x" * 100)
    fits = '{"data": "%s"}' % ("y" * 80)
    path = write(tmp_path, format_line("/a", 0, "{}") + format_line("/a", 1, fits) + format_line("/a", 2, big))
    with open_source(path) as src:
        assert len(list(src)) == 3  # no limit unless asked: `convert` writes any size
    with JsonlSource(path, max_text_bytes=len(fits)) as src:
        got = []
        with pytest.raises(SourceError, match=rf"log.jsonl, line 3: the message is {len(big)} bytes of JSON, "
                           rf"over the {len(fits)} bytes one record of a store holds"):  # fmt: skip
            for m in src:
                got.append(m.text)
    assert got == ["{}", fits]  # the messages before it, as for any bad line
    seen = []
    with open_source(path, on_error="skip", report=seen.append, max_text_bytes=len(fits)) as src:
        assert [m.stamp_ns for m in src] == [0, 1]
    assert len(seen) == 1 and "line 3" in str(seen[0])
    with JsonlSource(path, topics=["/b"], max_text_bytes=len(fits)) as src:
        assert list(src) == []  # a topic not read is no error, whatever its size


def test_the_text_limit_counts_the_message_not_the_line(tmp_path):
    msg = '{"s": "\\u00e9"}'  # far shorter than either line that holds it
    other = '{"msg": %s,   "stamp_ns": 5,          "topic": "/a"         }\n' % msg
    path = write(tmp_path, format_line("/a", 4, msg) + other)
    with JsonlSource(path, max_text_bytes=len(msg)) as src:
        assert [(m.stamp_ns, m.text) for m in src] == [(4, msg), (5, msg)]
    with JsonlSource(path, max_text_bytes=len(msg) - 1) as src, pytest.raises(SourceError, match=f"line 1: the message is {len(msg)} bytes"):
        list(src)
