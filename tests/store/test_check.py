"""Checks on what users hand to the store (store/check.py): nothing bad gets written."""

import pytest

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
