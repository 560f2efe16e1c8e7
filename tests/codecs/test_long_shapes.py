"""Shapes with long literals (a long string or key in a message) cost linear time and memory.

Found by an attack (issue 16): a message with a 4 MiB string took 5.5 s of CPU and 541 MiB
to encode, because its text was compiled into a regex (~130 bytes a character). Such a
shape is now matched by shapes._LongShape, which must find exactly the regex's values.
"""

from __future__ import annotations

import json
import re
import time

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.codecs import shapes
from cclogfs.codecs.columnar import ColumnarCodec
from cclogfs.codecs.shapes import split_text

# A regex of any shape tested here is far below this; the texts' own length is far above.
_LONGEST_PATTERN = 20_000
LONG = 1 << 20


def _raw_len(texts):
    return 4 + 12 * len(texts) + sum(len(t.encode()) for t in texts)


@pytest.fixture
def short_regexes(monkeypatch):
    """Fail at once when anything compiles a regex longer than _LONGEST_PATTERN."""
    compile_ = re.compile

    def spy(pattern, flags=0):
        assert len(pattern) < _LONGEST_PATTERN, f"a {len(pattern)}-character regex was compiled"
        return compile_(pattern, flags)

    monkeypatch.setattr(shapes.re, "compile", spy)


@pytest.mark.parametrize(
    "text",
    [
        json.dumps({"data": "x" * LONG}),
        json.dumps({"k" * LONG: 1}),
        json.dumps({"data": "y" * LONG, "n": 3, "frame": "map"}),
        json.dumps(["\\" * (LONG // 2), 1.5, '"' * 1000]),
    ],
)
@pytest.mark.parametrize("how", ["group_window", "group"])
def test_a_long_text_is_not_compiled_into_a_regex(short_regexes, row_path, text, how):
    # Alone (nothing to compare with: every value baked) and in a window of copies.
    for window in ([text], [text, text.replace("1", "2"), text]):
        groups, unshaped = getattr(shapes.ShapeMatcher(), how)(window)
        if how == "group":
            groups = [(literals, idx, rows) for literals, (idx, rows) in groups.items()]
        else:  # group_window gives value columns: back to rows (none when every value is baked)
            groups = [(literals, idx, list(zip(*(shapes.column_tokens(c, len(idx)) for c in cols))) if cols else [()] * len(idx))
                      for literals, idx, cols in groups]  # fmt: skip
        assert unshaped == []
        for literals, indices, rows in groups:
            for i, row in zip(indices, rows):
                assert "".join(a + b for a, b in zip(literals, [*row, ""])) == window[i]


def test_a_long_message_round_trips_through_the_codec(short_regexes):
    texts = [json.dumps({"data": "x" * LONG, "i": 1}), json.dumps({"data": "x" * LONG, "i": 2}), '{"i": 3}']
    codec = ColumnarCodec()
    payload = codec.encode([1, 2, 3], texts)
    assert codec.decode(payload, count=3, raw_len=_raw_len(texts)) == ([1, 2, 3], texts)


def test_baking_many_constants_after_a_long_literal_is_linear():
    # Each fixed value used to copy the whole literal so far: 4,000 copies of 1 MiB took
    # 1.5 s of CPU (and 4 MiB x 4,000 minutes); joined once it takes about a millisecond.
    literals = ("[" + "x" * LONG,) + (", ",) * 4000 + ("]",)
    values = ["1"] * 4001
    start = time.process_time()
    merged, kept = shapes.bake(literals, values, [True] * 4001)
    assert time.process_time() - start < 0.3
    assert merged == ("".join(a + b for a, b in zip(literals, [*values, ""])),) and kept == []


def test_baking_keeps_the_values_that_vary():
    literals, values = split_text('{"a": 1, "b": "s", "c": 2, "d": 3}')
    merged, kept = shapes.bake(literals, values, [True, False, True, True])
    assert merged == ('{"a": 1, "b": ', ', "c": 2, "d": 3}') and kept == ['"s"']


leaves = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6)
values_ = st.recursive(leaves, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3), max_leaves=8)  # fmt: skip
INSERTS = st.sampled_from(["", '"', "\\", "\\\\", '\\"', "x", "-", " ", ",", "\u00e9", "\u20ac", "\n", "1e5", '"a"'])


def _regex(literals, values):
    """`shapes._matcher`'s regex even for a shape it would match as a _LongShape."""
    if len(values) > shapes._MAX_MATCHER_SLOTS:
        return None
    return shapes._regex(literals, shapes._kinds(values))


def _matcher_without_the_row_finder(literals, values):
    """`shapes._matcher` as it is where the compiled row finder is not built: a regex for
    every shape under the limits (a _LongShape for every shape where it is built)."""
    if len(values) > shapes._MAX_MATCHER_SLOTS:
        return None
    if shapes._regex_is_cheap(literals, len(values)):
        return shapes._regex(literals, shapes._kinds(values))
    return shapes._LongShape(literals, shapes._kinds(values))


@settings(max_examples=300)
@given(st.builds(json.dumps, values_), st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 3), INSERTS), max_size=6))
def test_a_long_shape_matches_what_the_regex_matches(row_path, text, edits):
    split = split_text(text)
    if split is None:  # not every JSON text tokenizes (a key that looks like a number)
        return
    literals, values = split
    kinds = tuple(v.startswith('"') for v in values)
    regex = _regex(literals, values)
    if regex is None or isinstance(regex, shapes._LongShape):
        return
    long_shape = shapes._LongShape(literals, kinds)
    long_shape.short = False  # read as a long shape is (row finder or token by token), no regex
    candidates = [text]
    for at, cut, insert in edits:  # the text damaged: characters replaced, removed, added
        at %= len(text) + 1
        candidates.append(text[:at] + insert + text[at + cut :])
    for candidate in candidates:
        want, got = regex.fullmatch(candidate), long_shape.fullmatch(candidate)
        assert (None if want is None else want.groups()) == (None if got is None else got.groups())


@pytest.mark.parametrize("name", ["nav2_turtlebot.mcap", "tf_example.bag"])
def test_real_windows_encode_the_same_with_every_shape_matched_as_long(shared_data, monkeypatch, name):
    from cclogfs.ingest import open_source

    by_topic: dict[str, list[str]] = {}
    with open_source(str(shared_data(name))) as source:
        for m in source:
            by_topic.setdefault(m.topic, []).append(m.text)
    windows = [texts[i : i + 200] for texts in by_topic.values() for i in range(0, len(texts), 200)]

    def encode_all():
        codec = ColumnarCodec()  # one codec: a window's shape may come from the one before
        return [codec.encode(list(range(len(w))), w) for w in windows]

    with monkeypatch.context() as regexes:
        regexes.setattr(shapes, "_matcher", _matcher_without_the_row_finder)
        want = encode_all()
    assert encode_all() == want
    monkeypatch.setattr(shapes, "_MAX_REGEX_LITERALS", 0)
    assert encode_all() == want
    monkeypatch.setattr(shapes, "_MAX_REGEX_LITERALS", 4096)
    monkeypatch.setattr(shapes, "_MAX_REGEX_SLOTS", 0)
    assert encode_all() == want


def _varying_arrays(count=20, start=1900, step=7):
    """LaserScan-like messages whose ranges grow by `step` values a message: a new shape
    each, of ~2,000 value slots and under 4,096 literal characters."""
    texts = []
    for i in range(count):
        ranges = [round(0.1 + ((i * 7919 + j * 104729) % 9973) / 1000, 3) for j in range(start + step * i)]
        texts.append(json.dumps({"header": {"stamp": {"sec": 100 + i, "nanosec": 0}, "frame_id": "laser"},
                                 "ranges": ranges}))  # fmt: skip
    return texts


def test_many_varying_value_slots_compile_no_big_regex(short_regexes, row_path):
    # Each message compiled regexes of ~2,000 groups (60-90 us a slot): 20 of them took
    # 4-5 s of CPU to encode; read slot by slot they take ~0.1 s.
    texts = _varying_arrays()
    assert sum(map(len, split_text(texts[0])[0])) < 4096  # the old code compiled these
    codec = ColumnarCodec()
    payload = codec.encode(list(range(len(texts))), texts)
    assert codec.decode(payload, count=len(texts), raw_len=_raw_len(texts)) == (list(range(len(texts))), texts)


def test_many_varying_value_slots_encode_the_same_bytes_as_with_regexes(monkeypatch, row_path):
    texts = _varying_arrays(count=12, start=300, step=-11)  # 300 to 179 slots: both sides of the limit
    steady = [texts[0].replace("laser", "laser2")] * 5 + texts[:1] * 5  # a shape that repeats
    windows = [texts, texts[:3], steady, texts[::-1]]

    def encode_all():
        codec = ColumnarCodec()
        return [codec.encode(list(range(len(w))), w) for w in windows]

    want = encode_all()
    monkeypatch.setattr(shapes, "_MAX_REGEX_SLOTS", shapes._MAX_MATCHER_SLOTS)  # every shape a regex
    monkeypatch.setattr(shapes, "_matcher", _matcher_without_the_row_finder)
    assert encode_all() == want
