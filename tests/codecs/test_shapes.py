"""cclogfs.codecs.shapes: JSON texts cut into a shape (literals) and value tokens."""

import json
import random

import pytest

from cclogfs.codecs.shapes import ShapeMatcher, column_tokens, split_text

# Every test here runs on both row paths (tests/conftest.py: row_path).
pytestmark = pytest.mark.usefixtures("row_path")


def rebuild(literals, values):
    return "".join(a + b for a, b in zip(literals, list(values) + [""]))


@pytest.mark.parametrize(
    "text",
    ['{"a": 1, "b": [true, null, -2.5e3]}', '{ "s" : "x\\"y", "n":{"k":"v"} }', "[]", "17", '"just a string"'],
)
def test_split_text_rebuilds_the_text_byte_for_byte(text):
    literals, values = split_text(text)
    assert rebuild(literals, values) == text
    assert len(literals) == len(values) + 1


def test_keys_are_literals_and_values_are_tokens():
    literals, values = split_text('{"a": 1, "b": "two"}')
    assert values == ["1", '"two"'] and literals == ('{"a": ', ', "b": ', "}")


def test_trailing_text_is_kept_in_the_last_literal():
    # Shapes are about rebuilding bytes, not about JSON validity (the store checks that).
    assert split_text('{"a": 1 $}') == (('{"a": ', " $}"), ["1"])


@pytest.mark.parametrize("text", ['{"a": "unterminated}', "{'a': 1}"])
def test_a_text_that_does_not_tokenize_has_no_shape(text):
    assert split_text(text) is None


def window(n=40, seed=1):
    rng = random.Random(seed)
    texts = [json.dumps({"x": rng.random(), "frame": "map", "cov": [0.0] * 4, "i": i}) for i in range(n)]
    texts[7] = json.dumps({"other": True, "i": 7})
    texts[9] = None  # not UTF-8: never shaped
    texts[11] = "{'single': 'quotes'}"
    return texts


@pytest.mark.parametrize("how", ["group", "group_window"])
def test_grouping_covers_every_text_once_and_rebuilds_it(how):
    texts = window()
    groups, unshaped = getattr(ShapeMatcher(), how)(texts)
    if how == "group":
        groups = [(literals, indices, rows) for literals, (indices, rows) in groups.items()]
    else:  # group_window gives value columns: one per slot, one token per text (a number slot's one str)
        groups = [(literals, indices, list(zip(*(column_tokens(c, len(indices)) for c in columns))))
                  for literals, indices, columns in groups]  # fmt: skip
    seen = list(unshaped)
    for literals, indices, rows in groups:
        assert len(indices) == len(rows)
        for i, row in zip(indices, rows):
            assert rebuild(literals, row) == texts[i]
        seen += indices
    assert sorted(seen) == list(range(len(texts)))
    assert 9 in unshaped and 11 in unshaped
    assert len(groups) >= 2  # the odd message 7 does not share the others' shape


def test_group_window_folds_constant_values_into_the_literals():
    groups, _ = ShapeMatcher().group_window(window())
    main = max(groups, key=lambda g: len(g[1]))
    literals, indices, columns = main
    assert '"map"' in "".join(literals)  # constant in the window: no column spent on it
    assert len(columns) < len(split_text(window()[0])[1])


def test_compiled_shapes_are_bounded():
    matcher = ShapeMatcher(capacity=3)
    for k in range(10):
        matcher.group([json.dumps({f"key{k}": 1})])
    assert len(matcher._compiled) == 3


def _spy_compiles(monkeypatch):
    from cclogfs.codecs import shapes

    compiled = []

    def spy(literals, kinds):
        compiled.append(literals)
        return regex(literals, kinds)

    regex = shapes._regex
    monkeypatch.setattr(shapes, "_regex", spy)
    return compiled


def _windows(text_of):
    return [[text_of(w, i) for i in range(50)] for w in range(3)]


def test_the_compiled_row_finder_reads_every_shape_without_a_regex(monkeypatch, row_path):
    # A regex costs ~1.3 us a literal character to compile; smart logging stores a window
    # of a new shape nearly every time (issue 14, seventh pass).
    compiled = _spy_compiles(monkeypatch)
    ascii_windows = _windows(lambda w, i: json.dumps({"w": w, "x": i / 7, "frame": f"map{w}"}))
    wide_windows = _windows(lambda w, i: json.dumps({"w": w, "x": i / 7, "frame": "\u20ac"}, ensure_ascii=False))
    for windows in (ascii_windows, wide_windows):
        matcher, before = ShapeMatcher(), len(compiled)
        for texts in windows:
            groups, unshaped = matcher.group_window(texts)
            assert unshaped == []
            for literals, indices, columns in groups:
                for i, row in zip(indices, zip(*(column_tokens(c, len(indices)) for c in columns))):
                    assert rebuild(literals, row) == texts[i]
        if row_path == "python" or windows is wide_windows:
            assert len(compiled) > before  # texts the row finder declines: a regex per shape
        else:
            assert len(compiled) == before
