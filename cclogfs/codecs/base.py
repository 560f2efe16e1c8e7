"""The codec interface: a codec turns one window's messages into bytes and back.

Modelled on numcodecs: a codec has a string id, `encode`, `decode`, `get_config()`
(a JSON-able dict that includes the id) and `from_config()`. The store writes the config
into every record, so a record always says how to decode itself.

A window is two parallel sequences: `stamps` (int nanoseconds) and `texts` (each
message's JSON text as a `str`, exactly as put). Texts cross the boundary as `str`
because the columnar codec works on text: the store hands over what it was given and
gets back what it returns, with no UTF-8 round trip in between. Byte codecs frame the
UTF-8 themselves. Stored bytes that are not UTF-8 (the store never writes them, but a
payload can hold them) come back as surrogate escapes (PEP 383), so every payload
decodes to exactly the bytes it holds.

`raw_len` is the size of the canonical framing of the window in UTF-8 (see `raw_size`);
it comes from the record's checksummed header, and a decoder must never allocate more
than that (plus a constant), whatever the encoded bytes claim.
"""

from __future__ import annotations

import struct
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, ClassVar

from ..errors import CodecError

_COUNT = struct.Struct("<I")
# How texts become bytes and back at the codec's edge: UTF-8, any stray byte escaped.
UTF8_ERRORS = "surrogateescape"


def utf8_size(texts: Sequence[str]) -> int:
    """The UTF-8 byte length of the texts together. JSON is mostly ASCII, and an ASCII
    text's length is its byte length: only other texts are encoded to be measured. (No
    join: copying a window's texts costs more than the measuring, issue 14.)"""
    if all(map(str.isascii, texts)):
        return sum(map(len, texts))
    return sum(len(t.encode("utf-8", UTF8_ERRORS)) for t in texts)


def encode_texts(texts: Sequence[str]) -> list[bytes]:
    """The UTF-8 bytes of each text; a lone surrogate (not an escaped byte) is a CodecError."""
    try:
        return [t.encode("utf-8", UTF8_ERRORS) for t in texts]
    except UnicodeEncodeError as err:
        raise CodecError(f"a text holds {err.object[err.start:err.end]!r}, which UTF-8 cannot encode") from err


def raw_size(stamps: Sequence[int], texts: Sequence[str]) -> int:
    """Size of the canonical framing: u32 count, count*i64 stamps, count*u32 lengths, texts."""
    return 4 + 12 * len(stamps) + utf8_size(texts)


def frame(stamps: Sequence[int], texts: Sequence[str]) -> bytes:
    """The canonical framing of a window (what byte-oriented codecs compress)."""
    n = len(stamps)
    data = encode_texts(texts)
    head = struct.pack(f"<I{n}q{n}I", n, *stamps, *map(len, data))
    return head + b"".join(data)


def unframe(raw: bytes | memoryview, count: int) -> tuple[list[int], list[str]]:
    """Inverse of `frame`, checking every length against the buffer."""
    raw = memoryview(raw)
    if len(raw) < 4 + 12 * count or _COUNT.unpack_from(raw, 0)[0] != count:
        raise CodecError(f"decoded window framing does not hold {count} messages")
    stamps = list(struct.unpack_from(f"<{count}q", raw, 4))
    lengths = struct.unpack_from(f"<{count}I", raw, 4 + 8 * count)
    pos = 4 + 12 * count
    if pos + sum(lengths) != len(raw):
        raise CodecError("decoded window framing lengths do not add up to the payload size")
    texts = []
    for n in lengths:
        texts.append(str(raw[pos : pos + n], "utf-8", UTF8_ERRORS))
        pos += n
    return stamps, texts


class Codec(ABC):
    """Encodes the messages of one window; see the module docstring."""

    codec_id: ClassVar[str]

    @abstractmethod
    def encode(self, stamps: Sequence[int], texts: Sequence[str]) -> bytes:
        """Encode one window. Must be exactly reversible by `decode`."""

    @abstractmethod
    def decode(self, data: bytes, *, count: int, raw_len: int) -> tuple[list[int], list[str]]:
        """Decode one window of `count` messages whose framing is `raw_len` bytes."""

    def get_config(self) -> dict[str, Any]:
        """A JSON-able dict that recreates this codec through the registry."""
        return {"id": self.codec_id}

    @classmethod
    def from_config(cls, config: dict[str, Any]) -> "Codec":
        params = {k: v for k, v in config.items() if k != "id"}
        try:
            return cls(**params)
        except TypeError as err:
            raise CodecError(f"codec {cls.codec_id!r} does not accept config {config!r}") from err


class ByteCodec(Codec):
    """A general-purpose compressor applied to the canonical framing."""

    @abstractmethod
    def compress(self, raw: bytes) -> bytes: ...

    @abstractmethod
    def decompress(self, data: bytes, raw_len: int) -> bytes:
        """Must fail (CodecError) rather than produce more than raw_len bytes."""

    def encode(self, stamps: Sequence[int], texts: Sequence[str]) -> bytes:
        return self.compress(frame(stamps, texts))

    def decode(self, data: bytes, *, count: int, raw_len: int) -> tuple[list[int], list[str]]:
        raw = self.decompress(data, raw_len)
        if len(raw) != raw_len:
            raise CodecError(
                f"codec {self.codec_id!r} produced {len(raw)} bytes, the header says {raw_len}"
            )
        return unframe(raw, count)
