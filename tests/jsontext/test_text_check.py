"""The simdjson fast path never changes the answer of Python's json module."""

import json

from hypothesis import given, settings
from hypothesis import strategies as st

from cclogfs.jsontext.check import json_error, object_members

VALUES = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=5), kids, max_size=4),
    max_leaves=12,
)
ODD = st.sampled_from(["NaN", "-Infinity", "1e400", "123456789012345678901234567890", '"\\ud800"',
                       "\ufeff{}", " {} ", "{}\n", "01", "1.", ".5", "[1,]", '{"a":1,"a":2}', "[" * 2000,
                       "\t[\r\n1\n]", "'a'", "{}{}", '"\x01"', "-0.0", "1E5", "tru", ""])  # fmt: skip


def python_says(text):
    try:
        json.loads(text)
        return True
    except (ValueError, RecursionError):
        return False


@settings(max_examples=400)
@given(st.one_of(VALUES.map(json.dumps), VALUES.map(lambda v: json.dumps(v, indent=1)), ODD, st.text(max_size=30)))
def test_same_answer_as_python_json(text):
    assert (json_error(text) is None) == python_says(text)


@settings(max_examples=300)
@given(VALUES.map(json.dumps), st.integers(0, 10_000), st.sampled_from(["", "x", "}", ",", '"', "\\", " ", "\ufeff"]))
def test_same_answer_on_damaged_json(text, at, insert):
    at = at % (len(text) + 1)
    damaged = text[:at] + insert + text[at + 1 :]
    assert (json_error(damaged) is None) == python_says(damaged)


@settings(max_examples=300)
@given(st.one_of(VALUES.map(json.dumps), ODD, st.text(max_size=30)), st.sampled_from(["", "\n", " \r\n"]))
def test_a_member_count_is_one_python_json_agrees_with(text, ending):
    """object_members may decline (None) what json takes, never count what it refuses."""
    count = object_members((text + ending).encode("utf-8", "surrogatepass"))
    if count is not None:
        pairs = json.loads(text, object_pairs_hook=lambda p: ("object", len(p)))
        assert pairs == ("object", count)
