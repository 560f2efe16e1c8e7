"""Codec registry: maps codec ids (the string in a config, and the number in a record
header) to codec classes. New codecs register here; an unknown id is a clear error."""

from __future__ import annotations

import functools
import json
from enum import IntEnum
from typing import Any

from ..errors import CodecError, UnknownCodecError
from .base import Codec


class CodecId(IntEnum):
    """Codec numbers stored in record headers. 0 is invalid; values never change."""

    NONE = 1
    ZSTD = 2
    LZMA = 3
    COLUMNAR = 4


_BY_NAME: dict[str, type[Codec]] = {}
_NUMERIC: dict[str, CodecId] = {}


def register(cls: type[Codec], numeric_id: CodecId) -> type[Codec]:
    """Add a codec class under its string id and its on-disk numeric id."""
    _BY_NAME[cls.codec_id] = cls
    _NUMERIC[cls.codec_id] = numeric_id
    return cls


def registered_ids() -> list[str]:
    return sorted(_BY_NAME)


def codec_numeric_id(codec: Codec) -> CodecId:
    return _NUMERIC[codec.codec_id]


def codec_from_config(config: dict[str, Any] | str) -> Codec:
    """A codec instance from a config dict (or a bare id such as "zstd")."""
    if isinstance(config, str):
        config = {"id": config}
    if not isinstance(config, dict) or not isinstance(config.get("id"), str):
        raise CodecError(f"a codec config must be a dict with a string 'id', got {config!r}")
    cls = _BY_NAME.get(config["id"])
    if cls is None:
        raise UnknownCodecError(
            f"unknown codec {config['id']!r}; known codecs: {', '.join(registered_ids())}"
        )
    return cls.from_config(config)


@functools.lru_cache(maxsize=64)
def codec_for_record(config: bytes) -> Codec:
    """The codec a record's config bytes name, built once per distinct config.

    A store holds a handful of configs, so reads share one codec (one zstd context, one
    shape cache) per config instead of building one per window. Sharing across threads is
    safe: every codec keeps its zstd contexts and caches per thread (see simple, columnar).
    """
    try:
        parsed = json.loads(config)
    except (ValueError, RecursionError) as err:  # UnicodeDecodeError is a ValueError
        raise CodecError(f"codec config is not JSON: {str(err)[:80]}") from None
    try:
        return codec_from_config(parsed)
    except CodecError:
        raise
    except (TypeError, ValueError, KeyError, AttributeError, OverflowError) as err:
        # A config no writer produces (a forged or damaged record): a codec's from_config
        # trusts the shapes its own get_config wrote.
        raise CodecError(f"codec config {str(parsed)[:80]} is not valid: {type(err).__name__}: {err}") from None
