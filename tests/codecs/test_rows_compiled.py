"""The compiled row finder (cclogfs/codecs/_rows.c) gives exactly the re module's rows
and columns, and so the columnar encoder writes the same bytes with it as without it; its
row join gives exactly the texts of the decoder's % template."""

from __future__ import annotations

import json

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.codecs import columnar, shapes
from cclogfs.codecs.columnar import ColumnarCodec
from cclogfs.codecs.shapes import _kinds, _regex, split_text

try:  # as built, whatever the row_path fixture sets in shapes later
    from cclogfs.codecs import _rows as COMPILED
except ImportError:
    COMPILED = None
pytestmark = pytest.mark.skipif(COMPILED is None, reason="cclogfs.codecs._rows is not built")

leaves = st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=6)
values = st.recursive(leaves, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3), max_leaves=8)  # fmt: skip
texts = st.builds(json.dumps, values, ensure_ascii=st.booleans())
# What a damaged or other text may hold where the shape's text has something else.
INSERTS = st.sampled_from(["", '"', "\\", "\\\\", "\\\"", "x", "-", " ", ",", "é", "\u20ac", "\n", "1e5", '"a"'])


def regex_rows(literals, values, candidates):
    pattern = _regex(literals, _kinds(values))
    return [None if m is None else m.groups() for m in map(pattern.fullmatch, candidates)]


@settings(max_examples=500)
@given(texts, st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 3), INSERTS), max_size=6), st.lists(texts, max_size=3))
def test_the_same_rows_as_the_regex(text, edits, others):
    split = split_text(text)
    if split is None or len(split[1]) > shapes._MAX_MATCHER_SLOTS:
        return
    literals, values = split
    kinds = tuple(v.startswith('"') for v in values)
    candidates = [text, *others]
    for at, cut, insert in edits:  # the text damaged: characters replaced, removed, added
        at %= len(text) + 1
        candidates.append(text[:at] + insert + text[at + cut :])
    got = COMPILED.match_rows(literals, kinds, candidates)
    if got is NotImplemented:  # a text or literal of more than one byte per character
        assert not all(t.isascii() or max(map(ord, t)) < 256 for t in [*candidates, *literals])
        assert COMPILED.match_columns(literals, kinds, candidates) is NotImplemented
        return
    want = regex_rows(literals, values, candidates)
    assert got == want
    # By column: the rows transposed when every candidate matches (a number slot's tokens
    # joined by ",", or its one token when all are the same), else None.
    columns = COMPILED.match_columns(literals, kinds, candidates)
    if None in want:
        assert columns is None
    else:
        by_slot = shapes.transpose(want, len(kinds))
        assert columns == [list(c) if s else c[0] if len(set(c)) == 1 else ",".join(c) for c, s in zip(by_slot, kinds)]
        assert [list(shapes.column_tokens(c, len(candidates))) for c in columns] == [list(c) for c in by_slot]
        # and the Python path (shapes._columns without the helper) gives the same
        assert columns == [list(c) if s else shapes._number_column(c) for c, s in zip(by_slot, kinds)]


def test_edges_of_string_and_number_tokens():
    literals, kinds = ('{"s": ', ', "n": ', "}"), (True, False)
    candidates = ['{"s": "a\\"b", "n": -1.5e+3}', '{"s": "a\\", "n": 1}', '{"s": "a\\\\", "n": 1}', '{"s": "x", "n": }',
                  '{"s": "x", "n": 1 }', '{"s": "\xe9", "n": nan}', '{"s": "x\n", "n": 1}', '{"s": "x", "n": 1}}']  # fmt: skip
    want = regex_rows(literals, ['"s"', "0"], candidates)
    assert COMPILED.match_rows(literals, kinds, candidates) == want
    assert COMPILED.match_columns(literals, kinds, candidates) is None
    assert COMPILED.match_columns(literals, kinds, [candidates[0], candidates[2]]) == [['"a\\"b"', '"a\\\\"'], "-1.5e+3,1"]
    # A number slot whose tokens are all the same is that one token; one that only shares
    # a prefix or a length with the first is not.
    assert COMPILED.match_columns(literals, kinds, [candidates[2], candidates[2]]) == [['"a\\\\"', '"a\\\\"'], "1"]
    ones = ['{"s": "x", "n": 1}', '{"s": "x", "n": 1}', '{"s": "x", "n": 10}', '{"s": "x", "n": 2}']
    assert COMPILED.match_columns(literals, kinds, ones[:2]) == [['"x"', '"x"'], "1"]
    assert COMPILED.match_columns(literals, kinds, ones[:3]) == [['"x"'] * 3, "1,1,10"]
    assert COMPILED.match_columns(literals, kinds, ones[1::2]) == [['"x"'] * 2, "1,2"]
    assert COMPILED.match_columns(("[]",), (), ["[]", "[]"]) == []  # no value slots: no columns
    assert want[0] == ('"a\\"b"', "-1.5e+3") and want[1] is None and want[2] == ('"a\\\\"', "1")


def test_wider_characters_are_left_to_the_regex():
    for match in (COMPILED.match_rows, COMPILED.match_columns):
        assert match(("[", "]"), (True,), ['["\u20ac"]']) is NotImplemented
        assert match(("[\u20ac", "]"), (False,), ["[1]"]) is NotImplemented


def _encode_both(windows):
    out = {}
    for path in ("compiled", "python"):
        if path == "python":
            shapes._match_rows_c = shapes._match_columns_c = None
        try:
            codec = ColumnarCodec()
            out[path] = [codec.encode(list(range(len(w))), w) for w in windows]
        finally:
            shapes._match_rows_c, shapes._match_columns_c = COMPILED.match_rows, COMPILED.match_columns
    return out["compiled"], out["python"]


@settings(max_examples=100, deadline=None)  # the first example imports the encoder's numpy
@given(st.lists(st.lists(texts, min_size=1, max_size=40), min_size=1, max_size=3))
def test_the_encoder_writes_the_same_bytes_either_way(windows):
    compiled, python = _encode_both(windows)
    assert compiled == python


@pytest.mark.parametrize("name", ["nav2_turtlebot.mcap", "tf_example.bag"])
def test_real_windows_encode_the_same_either_way(shared_data, name):
    from cclogfs.ingest import open_source

    by_topic: dict[str, list[str]] = {}
    with open_source(str(shared_data(name))) as source:
        for m in source:
            by_topic.setdefault(m.topic, []).append(m.text)
    for topic, texts in by_topic.items():
        windows = [texts[i : i + 200] for i in range(0, len(texts), 200)]
        compiled, python = _encode_both(windows)
        assert compiled == python, topic


# Characters of one byte (ASCII, Latin-1), wider ones (the join says NotImplemented), and %.
CHARS = st.sampled_from(["a", "0", '"', "%", "%s", "%%", "\\", "\n", "\x00", "\x7f", "\x80", "é", "\xff", "\u20ac", "\U0001f600"])
strings = st.lists(CHARS, max_size=5).map("".join)


@settings(max_examples=500)
@given(st.integers(1, 4), st.integers(0, 5), st.data())
def test_join_rows_gives_the_template_s_texts(k, n, data):
    literals = data.draw(st.lists(strings, min_size=k + 1, max_size=k + 1))
    columns = [data.draw(st.lists(strings, min_size=n, max_size=n)) for _ in range(k)]
    fmt = "%s".join(literal.replace("%", "%%") for literal in literals)
    want = [fmt % row for row in zip(*columns)]
    got = COMPILED.join_rows(tuple(literals), tuple(columns))
    if got is NotImplemented:
        assert any(max(map(ord, s), default=0) > 255 for s in [*literals, *(v for c in columns for v in c)])
        return
    assert got == want
    # An ASCII text must be made as one: str.isascii and the UTF-8 encoder trust the flag.
    assert [t.isascii() for t in got] == [t.isascii() for t in want]
    assert columnar.join_rows(literals, columns, n) == want


def test_join_rows_gives_a_text_of_one_piece_as_that_piece():
    # As % does: a window of a million bare numbers holds each once (test_codec_bombs.py).
    values = [str(10 + i) for i in range(5)]
    got = COMPILED.join_rows(("", ""), (values,))
    assert all(t is v for t, v in zip(got, values))
    assert COMPILED.join_rows(("", "x", ""), (["", ""], ["", ""])) == ["x", "x"]


@pytest.mark.parametrize("literals, columns", [(("a",), ()), (("a", "b"), (["1"], ["2"])), (("a", "b", "c"), (["1"], ["2", "3"])), (("a", "b"), ("1",))])
def test_join_rows_refuses_a_misfit(literals, columns):
    with pytest.raises(ValueError):
        COMPILED.join_rows(literals, columns)
