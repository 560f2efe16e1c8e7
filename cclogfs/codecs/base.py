"""The codec interface: a codec turns one window's messages into bytes and back.

Modelled on numcodecs: a codec has a string id, `encode`, `decode`, `get_config()`
(a JSON-able dict that includes the id) and `from_config()`. The store writes the config
into every record, so a record always says how to decode itself.

A window is two parallel sequences: `stamps` (int nanoseconds) and `texts` (the UTF-8
bytes of each message's JSON text, exactly as put). `raw_len` is the size of the
canonical framing of the window (see `raw_size`); it comes from the record's checksummed
header, and a decoder must never allocate more than that (plus a constant), whatever the
encoded bytes claim.
"""

from __future__ import annotations

import struct
from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import Any, ClassVar

from ..errors import CodecError

_COUNT = struct.Struct("<I")


def raw_size(stamps: Sequence[int], texts: Sequence[bytes]) -> int:
    """Size of the canonical framing: u32 count, count*i64 stamps, count*u32 lengths, texts."""
    return 4 + 12 * len(stamps) + sum(len(t) for t in texts)


def frame(stamps: Sequence[int], texts: Sequence[bytes]) -> bytes:
    """The canonical framing of a window (what byte-oriented codecs compress)."""
    n = len(stamps)
    head = struct.pack(f"<I{n}q{n}I", n, *stamps, *(len(t) for t in texts))
    return head + b"".join(texts)


def unframe(raw: bytes | memoryview, count: int) -> tuple[list[int], list[bytes]]:
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
        texts.append(bytes(raw[pos : pos + n]))
        pos += n
    return stamps, texts


class Codec(ABC):
    """Encodes the messages of one window; see the module docstring."""

    codec_id: ClassVar[str]

    @abstractmethod
    def encode(self, stamps: Sequence[int], texts: Sequence[bytes]) -> bytes:
        """Encode one window. Must be exactly reversible by `decode`."""

    @abstractmethod
    def decode(self, data: bytes, *, count: int, raw_len: int) -> tuple[list[int], list[bytes]]:
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

    def encode(self, stamps: Sequence[int], texts: Sequence[bytes]) -> bytes:
        return self.compress(frame(stamps, texts))

    def decode(self, data: bytes, *, count: int, raw_len: int) -> tuple[list[int], list[bytes]]:
        raw = self.decompress(data, raw_len)
        if len(raw) != raw_len:
            raise CodecError(
                f"codec {self.codec_id!r} produced {len(raw)} bytes, the header says {raw_len}"
            )
        return unframe(raw, count)
