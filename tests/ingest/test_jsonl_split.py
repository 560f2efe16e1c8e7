"""The compiled JSONL splitter (cclogfs/ingest/_jsonl_split.c) changes nothing a JSONL
source gives: on random, damaged and real lines, JsonlSource reads the same messages and
the same errors (file, line, reason) with it as without it, and each line the splitter
takes is read by `json` as exactly that message (bench/_fuzz_targets.py: jsonl_split)."""

from __future__ import annotations

import json

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from bench._fuzz_targets import jsonl_split, python_message
from cclogfs.errors import SourceError
from cclogfs.ingest import jsonl
from cclogfs.ingest.base import SourceMessage
from cclogfs.jsontext.lines import format_line

COMPILED = jsonl._split_lines_c  # as imported, whatever the split_path fixture sets later
pytestmark = pytest.mark.skipif(COMPILED is None, reason="cclogfs.ingest._jsonl_split is not built")

VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=5), kids, max_size=4),
    max_leaves=12,
)
MSGS = st.builds(json.dumps, st.dictionaries(st.text(max_size=5), VALUES, max_size=4),
                 ensure_ascii=st.booleans(), separators=st.sampled_from([None, (",", ":"), (" ,\t", " : ")]))  # fmt: skip
TOPICS = st.text(min_size=1, max_size=8)
STAMPS = st.integers(-(1 << 63), (1 << 63) - 1) | st.sampled_from([0, -(1 << 63), (1 << 63) - 1, 1 << 63, -1 - (1 << 63)])
# What a damaged line may hold where a good one has something else: JSON's edges, what json
# reads and the splitter must leave (NaN, huge numbers), and UTF-8 that Python's strict
# decoder refuses (overlong, surrogates, above U+10FFFF, lone continuation bytes).
INSERTS = st.sampled_from([b"", b'"', b"\\", b"}", b"{", b"[", b"]", b",", b":", b" ", b"\t", b"\r", b"\x00", b"\x1f",
                           b"\x7f", b"\xc3\xa9", b"\xe2\x82\xac", b"\xf0\x9f\x98\x80", b"\xff", b"\x80", b"\xc3",
                           b"\xc0\x80", b"\xc1\xbf", b"\xe0\x80\x80", b"\xed\xa0\x80", b"\xed\xbf\xbf", b"\xf4\x90\x80\x80",
                           b"\xf5\x80\x80\x80", b"\xef\xbb\xbf", b"NaN", b"-Infinity", b"1e400", b"-0", b"01", b"1.",
                           b".5", b"1e", b"+1", b"\\ud800", b"\\u12", b"\\x", b"\\/", b"true", b"nul", b"fals",
                           b'"msgtype": "a", ', b', "msgtype": "t"', b"12345678901234567890"])  # fmt: skip


def canonical(topic: str, stamp: int, msg: str) -> bytes:
    """A line in the canonical layout with the topic as raw UTF-8 (format_line escapes it)."""
    if '"' in topic or "\\" in topic or any(ord(c) < 0x20 for c in topic):
        return format_line(topic, stamp, msg).encode("utf-8", "surrogatepass")
    return f'{{"topic": "{topic}", "stamp_ns": {stamp}, "msg": {msg}}}\n'.encode("utf-8", "surrogatepass")


@st.composite
def damaged(draw, line):
    data = bytearray(line)
    for _ in range(draw(st.integers(0, 3))):
        at = draw(st.integers(0, len(data)))
        data[at : at + draw(st.integers(0, 2))] = draw(INSERTS)
    return bytes(data)


LINES = st.builds(canonical, TOPICS, STAMPS, MSGS).flatmap(lambda line: st.just(line) | damaged(line)) | st.binary(max_size=60)


def read(path, path_is_compiled, **options):
    """(messages, errors, skipped) of the file, each bad line skipped and reported; and the
    messages and error of the same file read with bad lines stopping the read."""
    jsonl._split_lines_c = COMPILED if path_is_compiled else None
    try:
        errors = []
        with jsonl.JsonlSource(path, on_error="skip", report=lambda e: errors.append(str(e)), **options) as source:
            skipping = (list(source), errors, source.skipped)
        stopped = []
        try:
            with jsonl.JsonlSource(path, **options) as source:
                for batch in source.batches():
                    stopped.extend(batch)
            stop = None
        except SourceError as err:
            stop = str(err)
        return skipping, (stopped, stop)
    finally:
        jsonl._split_lines_c = COMPILED


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(LINES, min_size=1, max_size=12), st.booleans())
def test_the_same_messages_and_errors_either_way(tmp_path, lines, select):
    path = tmp_path / "log.jsonl"
    path.write_bytes(b"".join(line if line.endswith(b"\n") else line + b"\n" for line in lines))
    options = {"topics": ["/odom", "a"]} if select else {}
    assert read(path, True, **options) == read(path, False, **options)
    jsonl_split(path.read_bytes())  # each line the splitter takes: json reads that message


@settings(max_examples=300, deadline=None)
@given(st.lists(LINES, min_size=1, max_size=8))
def test_a_line_taken_is_the_message_json_reads(lines):
    jsonl_split(b"".join(line.rstrip(b"\n") + b"\n" for line in lines))


SCALARS = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6)


def new_scalars(draw, value):
    """`value` with the same objects and arrays, some of its scalars drawn anew (of any kind)."""
    if isinstance(value, dict):
        return {key: new_scalars(draw, item) for key, item in value.items()}
    if isinstance(value, list):
        return [new_scalars(draw, item) for item in value]
    return draw(SCALARS) if draw(st.booleans()) else value


@st.composite
def one_layout(draw):
    """Lines of one topic whose messages share a layout, their scalars varying, some damaged:
    what the splitter's templates are for (a message matching its topic's last one but at
    its scalars is checked by comparing the text between them)."""
    base = draw(st.dictionaries(st.text(max_size=5), VALUES, max_size=4))
    topic = draw(st.sampled_from(["/a", "/b", "/c"]))
    dumps = {"ensure_ascii": draw(st.booleans()), "separators": draw(st.sampled_from([None, (",", ":"), (" ,\t", " : ")]))}
    lines = []
    for stamp in range(draw(st.integers(1, 10))):
        line = canonical(topic, stamp, json.dumps(new_scalars(draw, base), **dumps))
        lines.append(draw(st.just(line) | damaged(line)))
    return lines


@settings(max_examples=300, deadline=None)
@given(st.lists(one_layout(), min_size=1, max_size=4), st.randoms(use_true_random=False))
def test_templates_change_no_verdict(runs, random):
    """A line is taken or left by the splitter alike whether it is read with the lines
    before it (its topic's template from them) or alone (the grammar check), and a line
    taken is the message json reads."""
    lines = [line for run in runs for line in run]
    if random.random() < 0.5:  # topics interleaved
        random.shuffle(lines)
    lines = [line.rstrip(b"\n") + b"\n" for line in lines]
    together = COMPILED(lines, SourceMessage)
    assert together == [COMPILED([line], SourceMessage)[0] for line in lines]
    jsonl_split(b"".join(lines))


def test_templates_past_their_limits():
    """More scalars than a template keeps (1,024), a topic whose layout keeps changing (a
    template tried only now and then), more topics than templates (8): the same verdicts
    as line by line."""
    many = canonical("/m", 1, json.dumps({"v": list(range(1500))}))
    lines = [many, canonical("/m", 2, json.dumps({"v": list(range(1, 1501))}))]
    for i in range(60):  # the layout changes at every line, then settles
        lines.append(canonical("/t", i, json.dumps({"a": [0.5] * (1 + i % 3 if i < 40 else 2), "b": "x" * i})))
    for i in range(40):  # twenty topics in turn, each of its own layout
        lines.append(canonical(f"/topic{i % 20}", i, json.dumps({f"k{i % 20}": i, "s": "é" * (i % 3)})))
    lines.append(canonical("/t", 99, '{"a": [0.5, 0.5], "b": "' + "x" * 39 + '\\u00"}'))  # a bad escape at the end
    lines.append(canonical("/t", 99, '{"a": [0.5, 0.5], "b": "' + "x" * 39 + '"} '))  # a space after the msg
    together = COMPILED(lines, SourceMessage)
    assert together == [COMPILED([line], SourceMessage)[0] for line in lines]
    assert together[-2:] == [None, None] and None not in together[:-2]
    jsonl_split(b"".join(line.rstrip(b"\n") + b"\n" for line in lines))


def taken(line: bytes) -> bool:
    return COMPILED([line], SourceMessage)[0] is not None


DEEP = "[" * 511 + "]" * 511


@pytest.mark.parametrize("msg, want", [
    ("{}", True), ('{"a": 1e400}', True), ('{"a": NaN}', False), ('{"a": -Infinity}', False),
    ('{"a": "\\ud800"}', True), ('{"a": "\x7f"}', True), ('{"a": "\x01"}', False), ('{"a": 01}', False),
    ('{"a": -0}', True), ('{"a": 1.}', False), ('{"a": 1 }', True), ('{"a": [1,]}', False),
    ('{"a":1,"a":2}', True), ('{"a": ' + DEEP + "}", True), ('{"a": [' + DEEP + "]}", False),  # 512 levels, 513
    ('{"a": ' + "9" * 640 + "}", True), ('{"a": -' + "9" * 641 + "}", False),  # int() refuses past its digit limit
])  # fmt: skip
def test_which_messages_it_takes(msg, want):
    """Taken: exactly the Python path's message; else left to the Python path."""
    line = f'{{"topic": "/t", "stamp_ns": 1, "msg": {msg}}}\n'.encode()
    assert taken(line) == want
    if want:
        assert COMPILED([line], SourceMessage)[0] == python_message(line) == ("/t", 1, msg, "")


@pytest.mark.parametrize("raw, want", [
    (b"\xc3\xa9", True), (b"\xf4\x8f\xbf\xbf", True), (b"\xed\xa0\x80", False), (b"\xc0\xaf", False),
    (b"\xf4\x90\x80\x80", False), (b"\xe0\x9f\xbf", False), (b"\xf0\x8f\xbf\xbf", False),
])  # fmt: skip
def test_utf8_as_pythons_strict_decoder(raw, want):
    assert taken(b'{"topic": "/t' + raw + b'", "stamp_ns": 1, "msg": {}}') == want
    assert taken(b'{"topic": "/t", "stamp_ns": 1, "msg": {"' + raw + b'": 0}}') == want


@pytest.mark.parametrize("stamp, want", [
    ("-9223372036854775807", True), ("9223372036854775807", True), ("-9223372036854775808", False),
    ("9223372036854775808", False), ("00", False), ("-0", False), ("1.0", False),
])  # fmt: skip
def test_stamps(stamp, want):
    assert taken(f'{{"topic": "/t", "stamp_ns": {stamp}, "msg": {{}}}}'.encode()) == want


@pytest.mark.parametrize("ending, want", [(b"", True), (b"\n", True), (b"\r\n", True), (b"\r", False),
                                          (b" \n", False), (b"\n\n", False)])  # fmt: skip
def test_line_endings(ending, want):
    assert taken(b'{"topic": "/t", "stamp_ns": 1, "msg": {}}' + ending) == want


def test_it_refuses_what_is_not_a_list_of_bytes():
    with pytest.raises(TypeError):
        COMPILED([b"{}", "{}"], SourceMessage)
    with pytest.raises(TypeError):
        COMPILED((b"{}",), SourceMessage)
    with pytest.raises(TypeError):
        COMPILED([b"{}"], dict)


@pytest.mark.parametrize("name", ["nav2_turtlebot.mcap", "tf_example.bag", "long/slamfail_hospital.mcap"])
def test_every_line_of_real_logs(shared_data, tmp_path, name):
    """Every message of the real logs as a JSONL line (what `cclog convert` writes): the
    splitter takes each, and the source reads the same messages either way."""
    from cclogfs.ingest import open_source

    with open_source(str(shared_data(name))) as source:
        messages = list(source)
    bare = [format_line(m.topic, m.stamp_ns, m.text).encode() for m in messages]
    typed = [format_line(m.topic, m.stamp_ns, m.text, m.msgtype).encode() for m in messages]  # another layout
    assert None not in COMPILED(bare, SourceMessage)
    assert COMPILED(bare, SourceMessage) == jsonl._split_python(bare)
    path = tmp_path / "real.jsonl"
    path.write_bytes(b"".join(bare + typed))
    assert read(path, True) == read(path, False)
    untyped = [m._replace(msgtype="") for m in messages]
    assert read(path, True)[0][0] == [*untyped, *messages] and len(messages) > 500


def test_an_integer_json_refuses_for_its_length_is_refused_either_way(tmp_path):
    """json reads an integer by int(), which refuses more than 4300 digits: the compiled
    splitter took such a line (stored, exit 0), the Python path raised a bare ValueError."""
    path = tmp_path / "log.jsonl"
    good = canonical("/t", 1, '{"a": 1}')
    path.write_bytes(good + canonical("/t", 2, '{"a": ' + "9" * 5000 + "}") + good)
    for compiled in (True, False):
        (messages, errors, skipped), (_, stop) = read(path, compiled)
        assert len(messages) == 2 and skipped == 1 and len(errors) == 1
        assert "line 2" in stop and "4300 digits" in stop
