"""Turning a window handed to the store into a record: checked, encoded, waiting for its seq.

Shared by `Store.put_window` and compaction's replacements, so both check and encode the
same way (a replacement is held to every rule a put is).
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from ..codecs import Codec, codec_from_config, codec_numeric_id, raw_size, utf8_size
from ..errors import InvalidInputError
from .check import check_stream_name, encode_messages
from .format import MAX_CONFIG, MAX_MESSAGE_TEXT, MAX_META, MAX_RECORD_RAW, pack_record


@dataclass(frozen=True, slots=True)
class Encoded:
    """A checked, encoded window waiting for its seq and flags."""

    name: bytes
    stamps: list[int]
    meta: bytes
    config: bytes
    codec: int
    raw_len: int
    payload: bytes

    def pack(self, seq: int, flags: int = 0, synced: int | None = None) -> bytes:
        return pack_record(
            seq=seq, start_ns=self.stamps[0], end_ns=self.stamps[-1], count=len(self.stamps),
            codec=self.codec, name=self.name, config=self.config, meta=self.meta,
            raw_len=self.raw_len, payload=self.payload, flags=flags, synced=synced,
        )  # fmt: skip


def encode_meta(meta: Mapping[str, Any]) -> bytes:
    if not isinstance(meta, Mapping):
        raise InvalidInputError(f"meta must be a dict, got {type(meta).__name__}")
    try:
        data = json.dumps(dict(meta), separators=(",", ":"), allow_nan=False).encode()
    except (TypeError, ValueError) as err:
        raise InvalidInputError(f"meta is not JSON-serializable: {err}") from err
    if len(data) > MAX_META:
        raise InvalidInputError(f"meta is {len(data)} bytes as JSON, over the {MAX_META}-byte limit")
    return data


class Codecs:
    """The store's codecs for new records: a default, per-stream overrides, and the config
    bytes and number each puts in a record header (computed once per codec object)."""

    def __init__(self, default: Codec, per_stream: Mapping[str, Codec]):
        self.default = default
        self.per_stream = dict(per_stream)
        self._headers: dict[int, tuple[Codec, bytes, int]] = {}

    def for_stream(self, name: str, codec: Any = None) -> Codec:
        """`codec` (an id or config) when given, else the stream's codec."""
        return codec_from_config(codec) if codec is not None else self.per_stream.get(name, self.default)

    def header(self, codec: Codec) -> tuple[bytes, int]:
        """The config bytes and number that go in each record, cached per configured codec."""
        cached = self._headers.get(id(codec))
        if cached is None or cached[0] is not codec:
            config = json.dumps(codec.get_config(), separators=(",", ":")).encode()
            if len(config) > MAX_CONFIG:
                raise InvalidInputError(f"codec config is {len(config)} bytes, over {MAX_CONFIG}")
            cached = (codec, config, int(codec_numeric_id(codec)))
            if codec is self.default or codec in self.per_stream.values():
                self._headers[id(codec)] = cached
        return cached[1], cached[2]


def encode_window(codecs: Codecs, name: str, messages: Sequence[tuple[int, str]],
                  meta: Mapping[str, Any] | None, codec: Any, check_json: bool) -> Encoded:  # fmt: skip
    """Check and encode a window as one record (everything but its seq and flags), as a
    compaction's replacement must be; raises InvalidInputError."""
    parts = encode_parts(codecs, name, messages, meta, codec, check_json, split=False)
    return parts[0]


def encode_parts(codecs: Codecs, name: str, messages: Sequence[tuple[int, str]],
                 meta: Mapping[str, Any] | None, codec: Any, check_json: bool, *,
                 split: bool = True) -> list[Encoded]:  # fmt: skip
    """Check and encode a window: one record, or, when its raw size is over MAX_RECORD_RAW
    and `split`, consecutive records of consecutive messages, each with the window's meta
    (FORMAT.md, "Limits"). Raises InvalidInputError."""
    name_bytes = check_stream_name(name)
    stamps, texts = encode_messages(messages, check_json=check_json)
    meta_bytes = b"{}" if meta is None else encode_meta(meta)
    chosen = codecs.for_stream(name, codec)
    config, codec_number = codecs.header(chosen)
    raw_len = raw_size(stamps, texts)
    bounds = [(0, len(stamps))] if raw_len <= MAX_RECORD_RAW else split_bounds(name, texts) if split else None
    if bounds is None:
        raise InvalidInputError(f"window for {name!r} is {raw_len} bytes, over the {MAX_RECORD_RAW}-byte "
                                "record limit; split it into several windows")  # fmt: skip
    parts = []
    for lo, hi in bounds:
        s, t = stamps[lo:hi], texts[lo:hi]
        size = raw_len if len(bounds) == 1 else raw_size(s, t)
        parts.append(Encoded(name_bytes, s, meta_bytes, config, codec_number, size, chosen.encode(s, t)))
    return parts


def split_bounds(name: str, texts: Sequence[str]) -> list[tuple[int, int]]:
    """[lo, hi) message ranges whose canonical framing is each at most MAX_RECORD_RAW."""
    bounds, lo, size = [], 0, 4
    for i, text in enumerate(texts):
        cost = 12 + utf8_size([text])
        if 4 + cost > MAX_RECORD_RAW:
            raise InvalidInputError(f"message {i} for {name!r} is {cost - 12} bytes, over what one record "
                                    f"holds ({MAX_MESSAGE_TEXT} bytes of text)")  # fmt: skip
        if size + cost > MAX_RECORD_RAW:
            bounds.append((lo, i))
            lo, size = i, 4
        size += cost
    bounds.append((lo, len(texts)))
    return bounds
