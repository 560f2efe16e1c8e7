"""Is a text exactly one well-formed JSON value? The grammar is Python's `json` module's
(which also takes NaN, Infinity and integers of any size, as robots' producers write them).

simdjson validates without building Python objects, about 15x faster than `json` on
odometry messages; whatever it rejects (NaN, huge integers, lone surrogate escapes...) is
decided by `json` itself, so the fast path never changes the answer. It accepts one thing
`json` does not, a leading byte-order mark, which is checked first.
"""

from __future__ import annotations

import functools
import json
import re
import threading
import unicodedata

__all__ = ["NAME_MAX_BYTES", "json_error", "name_error", "object_members", "text_error"]

# A stream name's limit in a record header (store/format.py MAX_NAME; a test checks they agree),
# here so that a source can refuse a name per line before the store would refuse its window.
NAME_MAX_BYTES = 1024

_decoder = json.JSONDecoder()
_local = threading.local()  # a simdjson parser is not thread-safe


@functools.cache
def _simdjson():
    """The simdjson module, or None without it, the fast path being optional (`json` alone
    gives the same answers). Imported on first use: most commands that import this module
    check no JSON (`cclog cat`; issue 14). Cached, a missing module too."""
    try:
        import simdjson
    except ImportError:
        return None
    return simdjson


def _parser():
    """This thread's simdjson parser; None without simdjson."""
    parser = getattr(_local, "parser", None)
    if parser is None:
        if (simdjson := _simdjson()) is None:
            return None
        parser = _local.parser = simdjson.Parser()
    return parser


def json_error(text: str) -> str | None:
    """None when `text` is one JSON value (surrounding whitespace allowed), else why not."""
    if not text.startswith("\ufeff") and (parser := _parser()) is not None:
        try:
            parser.parse(text.encode("utf-8", "surrogatepass"))
            return None
        except Exception:  # noqa: BLE001 - any refusal is decided by json below
            pass
    try:
        _decoder.decode(text)
    except ValueError as err:  # JSONDecodeError, or int()'s refusal of a number too long
        return str(err)
    except RecursionError:
        return "nested too deeply"
    return None


def object_members(data: bytes) -> int | None:
    """How many members `data` (UTF-8 bytes) has when simdjson reads it as one JSON object,
    surrounding whitespace allowed; None when it does not (not an object, not valid UTF-8,
    or JSON simdjson refuses but `json` may take: NaN, huge numbers, lone surrogate
    escapes), or when simdjson is not installed. A count is a verdict `json` agrees with;
    None is not a verdict: decode and ask `json_error`. Duplicate keys count twice.

    For a JSONL line: checking its bytes at once costs one parse, not a decode, an
    encode and a parse of the message text (issue 14).
    """
    if data.startswith(b"\xef\xbb\xbf") or (parser := _parser()) is None:  # json refuses a BOM
        return None
    try:
        doc = parser.parse(data)
    except Exception:  # noqa: BLE001 - any refusal: not a verdict
        return None
    return len(doc) if isinstance(doc, _simdjson().Object) else None


# A lone surrogate: a str can hold one, UTF-8 cannot encode it.
_SURROGATE = re.compile("[\ud800-\udfff]")


def text_error(text: object, *, check_json: bool = True) -> str | None:
    """None when `text` can be stored as a message's JSON text, else why not, phrased to
    follow the message's name ("message 3 is not well-formed JSON: ...").

    The one message check of the store and the pipeline. `check_json=False` skips only the
    JSON parse, for texts a parser has just checked (a JSONL or bag source). A text must be
    encodable as UTF-8: ASCII is at once, any other unless it holds a lone surrogate.
    """
    if not isinstance(text, str):
        return f"has a {type(text).__name__} where the JSON text must be a str"
    if check_json and (why := json_error(text)) is not None:
        return f"is not well-formed JSON: {why}"
    if not text.isascii() and _SURROGATE.search(text):
        return "is not valid UTF-8 text: surrogates not allowed"
    return None


def name_error(name: str, max_bytes: int = NAME_MAX_BYTES) -> str | None:
    """None when the store takes `name` (non-empty) as a stream name, else why not, phrased to
    follow the name. Names are data, never paths (`../x` is fine); a control character is
    refused since it would garble every listing and error that prints the name."""
    try:
        size = len(name.encode("utf-8"))
    except UnicodeEncodeError as err:
        return f"is not valid UTF-8: {err.reason}"
    if size > max_bytes:
        return f"is {size} bytes as UTF-8, over the {max_bytes}-byte limit"
    for ch in name:
        if unicodedata.category(ch) == "Cc":
            return f"contains the control character {ch!r}"
    return None
