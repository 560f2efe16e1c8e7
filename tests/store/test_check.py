"""Checks on what users hand to the store (store/check.py): nothing bad gets written."""

from unittest.mock import patch

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.errors import InvalidInputError
from cclogfs.store.check import check_stream_name, encode_messages
from cclogfs.store.format import MAX_NAME


def test_stream_names():
    assert check_stream_name("/odom") == b"/odom"
    assert check_stream_name("../x é") == "../x é".encode()  # data, never a path
    assert check_stream_name("a" * MAX_NAME) == b"a" * MAX_NAME
    for bad, why in [(b"/a", "must be a str"), ("", "empty"), ("a\nb", "control character"),
                     ("\ud800", "not valid UTF-8"), ("é" * MAX_NAME, "over the")]:  # fmt: skip
        with pytest.raises(InvalidInputError, match=why):
            check_stream_name(bad)


def test_messages_are_encoded_in_order():
    stamps, texts = encode_messages([(1, '{"a": 1}'), (1, "[]"), (5, '"é"')])
    assert stamps == [1, 1, 5] and texts == ['{"a": 1}', "[]", '"é"']  # text stays str: codecs take text


@pytest.mark.parametrize("messages, why", [
    ([], "at least one message"),
    (None, "must be a sequence"),
    ([(1, "1"), (0, "1")], "before the previous"),
    ([(True, "1")], "got a bool"),
    ([(1.5, "1")], "must be an integer"),
    ([(1 << 63, "1")], "does not fit in 64 bits"),
    ([(1, b"1")], "must be a str"),
    ([(1, "{")], "not well-formed JSON"),
    ([(1, "9" * 5000)], "not well-formed JSON: Exceeds the limit"),  # int() refuses it: a bare ValueError before
    ([(1, '"\ud800"')], "not valid UTF-8"),
    ([(1,)], "not a \\(stamp_ns, json_text\\) pair"),
])  # fmt: skip
def test_bad_messages_are_refused_with_the_reason(messages, why):
    with pytest.raises(InvalidInputError, match=why):
        encode_messages(messages)


def test_check_json_false_skips_only_the_parse():
    assert encode_messages([(1, "{")], check_json=False)[1] == ["{"]
    with pytest.raises(InvalidInputError, match="before the previous"):
        encode_messages([(2, "1"), (1, "1")], check_json=False)


ITEMS = st.one_of(
    st.tuples(st.one_of(st.integers(-(1 << 64), 1 << 64), st.booleans(), st.floats(), st.just(np.int64(3))),
              st.one_of(st.text(max_size=4), st.sampled_from(['"\ud800"', "é\udfff"]), st.binary(max_size=2))),
    st.lists(st.integers(0, 9), min_size=1, max_size=3).map(tuple), st.none(), st.text(min_size=2, max_size=2),
)  # fmt: skip


def _outcome(messages):
    try:
        return encode_messages(messages, check_json=False)
    except InvalidInputError as err:
        return str(err)


@settings(max_examples=400, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 5), st.text(max_size=3)), min_size=1, max_size=8), st.lists(st.tuples(st.integers(0, 7), ITEMS), max_size=2))  # fmt: skip
def test_a_window_checked_at_once_gives_the_loops_answer(good, edits):
    """The whole-window checks (no JSON parse) take only what the loop takes, with the same
    result; anything else is left to the loop, which names the first bad message."""
    messages = sorted(good)
    for at, item in edits:
        messages[at % len(messages)] = item
    with patch("cclogfs.store.check._checked_at_once", lambda m: None):
        want = _outcome(messages)
    got = _outcome(messages)
    assert got == want and type(got) is type(want)
    if isinstance(want, tuple):
        assert list(map(type, got[0])) == list(map(type, want[0]))
