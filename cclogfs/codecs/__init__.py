"""Codecs: turn one window's messages into bytes and back. The registry (registry.py)
owns the string ids and the numeric ids stored in record headers."""

from __future__ import annotations

from .base import ByteCodec, Codec, frame, raw_size, unframe, utf8_size
from .columnar import ColumnarCodec
from .registry import (
    CodecId,
    codec_for_record,
    codec_from_config,
    codec_numeric_id,
    register,
    registered_ids,
)
from .simple import LzmaCodec, NoneCodec, ZstdCodec

__all__ = [
    "ByteCodec",
    "Codec",
    "CodecId",
    "codec_for_record",
    "codec_from_config",
    "codec_numeric_id",
    "frame",
    "raw_size",
    "register",
    "registered_ids",
    "unframe",
    "utf8_size",
]

register(NoneCodec, CodecId.NONE)
register(ZstdCodec, CodecId.ZSTD)
register(LzmaCodec, CodecId.LZMA)
register(ColumnarCodec, CodecId.COLUMNAR)
