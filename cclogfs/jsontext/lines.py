"""The JSON Lines line format that ingest reads and export writes:
`{"topic": .., "stamp_ns": .., "msg": {..}}` (and an optional "msgtype"), one per line.

The `msg` text is kept byte for byte as it appears in the line (its exact slice), so
what goes into the store is what the producer wrote, and `convert` then `cat` gives the
same file back.

Speed: lines in the layout `format_line` writes take a fast path: one regular expression
for the head, and one check of the whole line as JSON (`split_canonical_bytes`, on the
line's bytes: no decode before the check); any other layout (other key order, spacing, escapes in the topic) goes through a
small scanner over the top-level object that uses the json module for every value.
"""

from __future__ import annotations

import functools
import json
import re
from collections.abc import Sequence
from itertools import chain
from json.decoder import scanstring

from ..errors import InvalidInputError
from .check import json_error, object_members

__all__ = ["JsonlLineError", "format_line", "format_lines", "parse_general", "parse_line", "split_canonical", "split_canonical_bytes"]

# The layout format_line() writes; anything else takes the general path.
_HEAD = r'\{"topic": "([^"\\\x00-\x1f]+)", "stamp_ns": (0|-?[1-9][0-9]{0,18}), "msg": '
_FAST_HEAD = re.compile(_HEAD + r"(?=\{)")
# The same layout as a whole line of bytes, its line ending included. The greedy ".*"
# jumps to the end and backs off to the last "}}", so matching costs no scan of the message.
_FAST_LINE = re.compile((_HEAD + r"(\{.*\})\}(?:\r?\n)?").encode(), re.S)
_WS = re.compile(r"[ \t\n\r]*")
_DECODER = json.JSONDecoder()
_REQUIRED = ("topic", "stamp_ns", "msg")
_OPTIONAL = ("msgtype",)
_MIN_STAMP, _MAX_STAMP = -(1 << 63), (1 << 63) - 1  # int64 nanoseconds, as the store keeps them


# Characters str.splitlines() (and so many a reader of lines) breaks a line at that JSON
# leaves raw once not everything is escaped: kept escaped, so a line stays one line.
_LINE_BREAKS = {0x85: "\\u0085", 0x2028: "\\u2028", 0x2029: "\\u2029"}


@functools.lru_cache(maxsize=4096)  # a log has few topics; json.dumps of the name was a tenth of writing a line
def _topic_json(topic: str) -> str:
    """The topic as a JSON string, as it came in: UTF-8 (as the msg text beside it), not
    \\u-escaped ("/c\\u00e1mara" for "/cámara"); quotes, backslashes, control characters and
    line separators escaped. Topics are valid UTF-8 (a line whose topic is not is refused)."""
    return json.dumps(topic, ensure_ascii=False).translate(_LINE_BREAKS)


def format_line(topic: str, stamp_ns: int, text: str, msgtype: str = "") -> str:
    """One JSONL line (with its newline) holding `text` unchanged as the `msg` value."""
    if "\n" in text or "\r" in text:
        raise InvalidInputError(
            f"The message on {topic} at {stamp_ns} ns contains a line break, so it cannot "
            "stay byte-exact on one JSON Lines line."
        )
    head = f'{{"topic": {_topic_json(topic)}, "stamp_ns": {int(stamp_ns)}, "msg": '
    if msgtype:
        return f'{head}{text}, "msgtype": {json.dumps(msgtype)}}}\n'
    return f"{head}{text}}}\n"


def format_lines(topic: str, messages: Sequence[tuple[int, str]]) -> str:
    """The lines `format_line` writes for each (stamp_ns, text) of one topic, joined.

    For a window's worth of messages at once: the line's %-template repeated once per
    message and filled in one call, with the stamps and texts interleaved, so no string
    is made per message (per message, `format_line`, the join and the `write` were a
    fifth of a full scan). The line-break check looks at each text with `in` (a memchr),
    not with a count of LF over the result (a byte loop, 5 % of a full scan).
    """
    line = '{"topic": ' + _topic_json(topic).replace("%", "%%") + ', "stamp_ns": %d, "msg": %s}\n'
    if any("\n" in text or "\r" in text for _, text in messages):
        for stamp, text in messages:
            format_line(topic, stamp, text)  # raises for the first text with a line break
    return (line * len(messages)) % tuple(chain.from_iterable(messages))


class JsonlLineError(ValueError):
    """Why one line is not a message; JsonlSource adds the file name and line number."""


def split_canonical(line: str) -> tuple[str, int, str] | None:
    """(topic, stamp_ns, msg text) of a line in the layout `format_line` writes, the msg
    text not yet checked to be JSON; None for any other layout (see `parse_general`)."""
    m = _FAST_HEAD.match(line)
    if m is None or line[-1] != "}" or line[-2] in " \t\r\n":
        return None
    # msg starts with "{" (the regex looks ahead), so line[start:-1] is exactly the msg
    # value when it is one valid value with no whitespace before the final "}".
    stamp = int(m.group(2))
    if not _MIN_STAMP <= stamp <= _MAX_STAMP:
        return None
    return m.group(1), stamp, line[m.end() : -1]


def split_canonical_bytes(raw: bytes) -> tuple[str, int, str] | None:
    """(topic, stamp_ns, msg text) of a line's bytes (its line ending allowed) in the layout
    `format_line` writes, the whole line checked to be JSON; None for any other layout, and
    for any line the check does not settle (decode it and take `parse_line`).

    The line must be one object of exactly three members: with the head matched and "}}"
    at its end, its third member's value (an object, so it ends in "}") is exactly the
    msg slice.
    """
    m = _FAST_LINE.fullmatch(raw)
    if m is None:
        return None
    topic, stamp, msg = m.groups()
    stamp = int(stamp)
    if not _MIN_STAMP <= stamp <= _MAX_STAMP or object_members(raw) != 3:
        return None
    # Valid UTF-8 (simdjson checked it): these decodes cannot fail.
    return topic.decode(), stamp, msg.decode()


def parse_line(line: str) -> tuple[str, int, str, str]:
    """(topic, stamp_ns, msg text, msgtype) of one line without its line ending."""
    parts = split_canonical(line)
    if parts is not None and json_error(parts[2]) is None:
        return (*parts, "")
    return parse_general(line)


def parse_general(line: str) -> tuple[str, int, str, str]:
    """Any layout of the object: scan its top level, let the json module read each value."""
    try:
        fields = _scan_object(line)
    except RecursionError:
        raise JsonlLineError("invalid JSON: nested too deeply") from None
    except ValueError as err:
        # The json module's own message (with column) is the clearest for broken JSON.
        try:
            json.loads(line)
        except ValueError as json_err:
            raise JsonlLineError(f"invalid JSON: {json_err}") from None
        raise JsonlLineError(str(err)) from None
    missing = [k for k in _REQUIRED if k not in fields]
    if missing:
        raise JsonlLineError(f"the object has no {', '.join(repr(k) for k in missing)} key")
    extra = [k for k in fields if k not in _REQUIRED and k not in _OPTIONAL]
    if extra:
        raise JsonlLineError(f"unknown key {extra[0]!r} (expected topic, stamp_ns, msg, msgtype)")
    topic, _, _ = fields["topic"]
    stamp, _, _ = fields["stamp_ns"]
    msg, start, end = fields["msg"]
    msgtype = fields.get("msgtype", ("", 0, 0))[0]
    if not isinstance(topic, str) or not topic:
        raise JsonlLineError("'topic' must be a non-empty string")
    if type(stamp) is not int or not _MIN_STAMP <= stamp <= _MAX_STAMP:
        raise JsonlLineError(f"'stamp_ns' must be a 64-bit integer, not {stamp!r}")
    if not isinstance(msg, dict):
        raise JsonlLineError(f"'msg' must be a JSON object, not {type(msg).__name__}")
    if not isinstance(msgtype, str):
        raise JsonlLineError("'msgtype' must be a string")
    return topic, stamp, line[start:end], msgtype


def _scan_object(line: str) -> dict[str, tuple[object, int, int]]:
    """Top-level keys of a one-object line -> (value, start, end) of each value's text."""
    i = _WS.match(line, 0).end()
    if line[i : i + 1] != "{":
        raise ValueError("a line must hold one JSON object")
    i = _WS.match(line, i + 1).end()
    fields: dict[str, tuple[object, int, int]] = {}
    if line[i : i + 1] == "}":
        i += 1
    else:
        while True:
            if line[i : i + 1] != '"':
                raise ValueError("expected a key")
            key, i = scanstring(line, i + 1)
            i = _WS.match(line, i).end()
            if line[i : i + 1] != ":":
                raise ValueError("expected ':'")
            start = _WS.match(line, i + 1).end()
            value, i = _DECODER.raw_decode(line, start)
            if key in fields:
                raise ValueError(f"duplicate key {key!r}")
            fields[key] = (value, start, i)
            i = _WS.match(line, i).end()
            sep = line[i : i + 1]
            i += 1
            if sep == "}":
                break
            if sep != ",":
                raise ValueError("expected ',' or '}'")
            i = _WS.match(line, i).end()
    if _WS.match(line, i).end() != len(line):
        raise ValueError("text after the object")
    return fields
