"""The JSON Lines line format: what export renders, ingest parses back exactly."""

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.errors import InvalidInputError
from cclogfs.jsontext.lines import JsonlLineError, format_line, format_lines, parse_line, split_canonical, split_canonical_bytes

topics = st.text(min_size=1, max_size=12)  # any name: quotes, escapes, non-ASCII
stamps = st.integers(min_value=-(1 << 63), max_value=(1 << 63) - 1)
leaves = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8)
values = st.recursive(leaves, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3), max_leaves=10)  # fmt: skip
# A msg is any JSON object in any spelling json.dumps writes on one line.
msgs = st.builds(json.dumps, st.dictionaries(st.text(max_size=5), values, max_size=4),
                 ensure_ascii=st.booleans(), separators=st.sampled_from([None, (",", ":"), (" , ", " :  ")]))  # fmt: skip
msgtypes = st.sampled_from(["", "nav_msgs/msg/Odometry", 'odd "type"'])


@settings(max_examples=200)
@given(topics, stamps, msgs, msgtypes)
def test_parse_of_render_gives_the_message_back(topic, stamp, msg, msgtype):
    line = format_line(topic, stamp, msg, msgtype)
    assert line.endswith("\n") and line.count("\n") == 1
    assert parse_line(line[:-1]) == (topic, stamp, msg, msgtype)


@given(topics, stamps, msgs)
def test_render_of_parse_gives_the_line_back_byte_for_byte(topic, stamp, msg):
    line = format_line(topic, stamp, msg)
    assert format_line(*parse_line(line[:-1])).encode("utf-8") == line.encode("utf-8")


def test_the_rendered_layout_is_pinned():
    assert format_line("/odom", 5, '{"x": 1}') == '{"topic": "/odom", "stamp_ns": 5, "msg": {"x": 1}}\n'
    # The topic as it came in, UTF-8 (it was \\u-escaped, l-left8); line separators stay escaped.
    assert format_line("/é", -1, "{}", "T") == '{"topic": "/é", "stamp_ns": -1, "msg": {}, "msgtype": "T"}\n'
    assert format_line('/"\\\x01\u2028\x85', 0, "{}") == \
        '{"topic": "/\\"\\\\\\u0001\\u2028\\u0085", "stamp_ns": 0, "msg": {}}\n'


def test_the_fast_split_takes_only_the_rendered_layout():
    assert split_canonical('{"topic": "/a", "stamp_ns": 7, "msg": {"k": 1}}') == ("/a", 7, '{"k": 1}')
    for other in ('{"stamp_ns": 7, "topic": "/a", "msg": {}}', '{"topic": "/a", "stamp_ns": 7, "msg": {} }',
                  '{"topic": "/a", "stamp_ns": 9223372036854775808, "msg": {}}'):  # fmt: skip
        assert split_canonical(other) is None


def test_a_message_nested_too_deeply_is_a_line_error_not_a_recursion_error():
    # Seen with `cclog record`/`convert` on a crafted line: a RecursionError traceback.
    import pytest

    from cclogfs.jsontext.lines import JsonlLineError

    line = '{"topic":"/a","stamp_ns":1,"msg":' + "[" * 5000 + "]" * 5000 + "}"
    with pytest.raises(JsonlLineError, match="nested too deeply"):
        parse_line(line)


def _parsed(raw: bytes):
    """What the general path makes of a line's bytes: its message, or None for an error."""
    try:
        line = raw.decode("utf-8")
        line = line[:-2] if line.endswith("\r\n") else line[:-1] if line.endswith("\n") else line
        topic, stamp, msg, msgtype = parse_line(line)
    except (UnicodeDecodeError, JsonlLineError):
        return None
    return (topic, stamp, msg) if not msgtype else None


ENDINGS = st.sampled_from(["\n", "\r\n", "", " \n"])
DAMAGE = st.sampled_from(["", "}", " ", ",", '"', "\\", "x", "\x00", "\ufeff", ', "msg": {}', ', "extra": 1', "NaN", "\ud800"])


@settings(max_examples=400)
@given(topics, stamps, msgs, msgtypes, ENDINGS, DAMAGE, st.integers(0, 10_000))
def test_the_fast_bytes_split_agrees_with_the_general_parse(topic, stamp, msg, msgtype, ending, insert, at):
    """Whatever line it settles (None: the caller asks parse_line), it settles as
    parse_line does, damaged lines and other layouts included."""
    line = format_line(topic, stamp, msg, msgtype)[:-1] + ending
    at = at % (len(line) + 1)
    for text in (line, line[:at] + insert + line[at:]):
        raw = text.encode("utf-8", "surrogatepass")  # a lone surrogate: bytes that are not UTF-8
        fast = split_canonical_bytes(raw)
        if fast is not None:
            assert fast == _parsed(raw)


def test_the_fast_bytes_split_takes_only_the_rendered_layout():
    assert split_canonical_bytes(b'{"topic": "/a", "stamp_ns": 7, "msg": {"k": {}}}\r\n') == ("/a", 7, '{"k": {}}')
    assert split_canonical_bytes('{"topic": "/\u00e9", "stamp_ns": 0, "msg": {"\u00e9": 1}}'.encode()) == ("/\u00e9", 0, '{"\u00e9": 1}')
    for other in (b'{"topic": "/a", "stamp_ns": 7, "msg": {} }', b'{"topic": "/a", "stamp_ns": 7, "msg": {}, "msg": {}}',
                  b'{"topic": "/a", "stamp_ns": 7, "msg": {}, "msgtype": "T"}', b'{"topic": "/a", "stamp_ns": 7, "msg": {"x": NaN}}',
                  b'{"topic": "/a", "stamp_ns": 9223372036854775808, "msg": {}}', b'{"topic": "/a", "stamp_ns": 7, "msg": {"\xff": 1}}'):  # fmt: skip
        assert split_canonical_bytes(other) is None


@given(
    st.text(st.characters(blacklist_categories=("Cs",)), min_size=1),
    st.lists(st.tuples(st.integers(-(1 << 63), (1 << 63) - 1), st.sampled_from(['{}', '{"a": "%s %d"}', '{"\\u00e9": 1}']))),
)
def test_format_lines_is_format_line_joined(topic, messages):
    # A topic or text with "%" in it must not be taken for part of the template.
    assert format_lines(topic, messages) == "".join(format_line(topic, s, t) for s, t in messages)


@pytest.mark.parametrize("brk", ["\n", "\r"])
def test_format_lines_names_a_text_with_a_line_break(brk):
    with pytest.raises(InvalidInputError, match="at 2 ns contains a line break"):
        format_lines("/a", [(1, "{}"), (2, "{" + brk + "}"), (3, "{}")])
