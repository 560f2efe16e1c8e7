"""General-purpose codecs over the canonical framing: none, zstd and LZMA."""

from __future__ import annotations

import io
import lzma
import threading

import zstandard

from ..errors import CodecError
from .base import ByteCodec


def read_zstd(dctx: zstandard.ZstdDecompressor, data: bytes | memoryview, size: int, what: str) -> bytes:
    """Exactly `size` bytes from one zstd frame, else CodecError naming `what`.

    zstd would trust a frame's declared content size and allocate it, so the frame is read
    as a stream, at most size + 1 bytes: a forged frame cannot make us allocate more than
    the checksummed header allows.
    """
    try:
        with dctx.stream_reader(io.BytesIO(data), read_across_frames=False) as reader:
            out = reader.read(size + 1)
    except zstandard.ZstdError as err:
        raise CodecError(f"{what} does not decode: {err}") from err
    if len(out) != size:
        raise CodecError(f"{what} decodes to more or less than the {size} bytes stated")
    return out


class NoneCodec(ByteCodec):
    """Stores the framing as it is."""

    codec_id = "none"

    def compress(self, raw: bytes) -> bytes:
        return raw

    def decompress(self, data: bytes, raw_len: int) -> bytes:
        return bytes(data)


class ZstdCodec(ByteCodec):
    """zstd with reused contexts (one per thread: zstd contexts are not thread-safe)."""

    codec_id = "zstd"

    def __init__(self, level: int = 3):
        if not isinstance(level, int) or not -7 <= level <= 22:
            raise CodecError(f"zstd level must be an integer in -7..22, got {level!r}")
        self.level = level
        self._local = threading.local()

    def get_config(self) -> dict:
        return {"id": self.codec_id, "level": self.level}

    def _contexts(self) -> tuple[zstandard.ZstdCompressor, zstandard.ZstdDecompressor]:
        ctx = getattr(self._local, "ctx", None)
        if ctx is None:
            ctx = (zstandard.ZstdCompressor(level=self.level), zstandard.ZstdDecompressor())
            self._local.ctx = ctx
        return ctx

    def compress(self, raw: bytes) -> bytes:
        return self._contexts()[0].compress(raw)

    def decompress(self, data: bytes, raw_len: int) -> bytes:
        return read_zstd(self._contexts()[1], data, raw_len, "zstd payload")


class LzmaCodec(ByteCodec):
    """LZMA (xz container), the paper's best general-purpose compressor."""

    codec_id = "lzma"

    def __init__(self, preset: int = 6):
        if not isinstance(preset, int) or not 0 <= preset <= 9:
            raise CodecError(f"lzma preset must be an integer in 0..9, got {preset!r}")
        self.preset = preset

    def get_config(self) -> dict:
        return {"id": self.codec_id, "preset": self.preset}

    def compress(self, raw: bytes) -> bytes:
        return lzma.compress(raw, preset=self.preset)

    def decompress(self, data: bytes, raw_len: int) -> bytes:
        dec = lzma.LZMADecompressor()
        try:
            out = dec.decompress(data, max_length=raw_len + 1)
        except lzma.LZMAError as err:
            raise CodecError(f"lzma payload does not decode: {err}") from err
        if len(out) != raw_len or not dec.eof:
            raise CodecError(f"lzma payload decodes to more or less than the {raw_len} bytes stated")
        return out
