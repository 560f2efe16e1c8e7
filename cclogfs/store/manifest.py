"""The manifest as an object: one immutable version of the store's catalogue.

The store, recovery and compaction share it as LevelDB's DBImpl holds a VersionSet: each
change (a segment sealed, segments rewritten as a new generation, the oldest dropped) builds
the next version, which `commit` makes durable by one atomic replace of the MANIFEST file.
A version reads like the JSON body on disk (`manifest["segments"]`), and never changes.
"""

from __future__ import annotations

import time
import uuid
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from functools import cached_property
from typing import Any

from ..errors import CorruptionError, StoreError
from .format import (
    FORMAT_VERSION,
    FORMAT_VERSIONS,
    Reason,
    RecordError,
    index_name,
    manifest_size_limit,
    pack_manifest,
    segment_name,
    unpack_manifest,
)
from .fs import FileSystem, FileTooLargeError
from .index import merge_stream_stats
from .manifest_check import body_version, check_body


@dataclass(frozen=True)
class SealedSegment:
    """A sealed segment as the manifest describes it (what upkeep and fsck plan with)."""

    first_seq: int
    end_seq: int
    size: int  # bytes of the segment file
    gen: int  # how often compaction rewrote it (names its files)
    streams: dict[str, dict[str, int]]  # per stream: windows, messages, start_ns, end_ns, raw_bytes, stored_bytes
    aged: dict[str, int]  # per stream: windows flagged AGED
    damaged: tuple[dict[str, Any], ...] = ()  # the damage the manifest names in it (Store.damage() entries)

    @classmethod
    def from_info(cls, info: Mapping[str, Any]) -> SealedSegment:
        return cls(info["first_seq"], info["end_seq"], info["size"], info.get("gen", 0),
                   info["streams"], dict(info.get("aged", {})), tuple(info.get("damaged", ())))  # fmt: skip

    def damage_dropped(self) -> list[dict[str, Any]]:
        """Its named damage as retention reports it when dropping it (each entry naming the
        segment file): what `drop_oldest` returns and what `compact --dry-run` foretells."""
        name = segment_name(self.first_seq, self.gen)
        return [dict(d, segment=name) for d in self.damaged]


class Manifest(Mapping[str, Any]):
    """One version of the manifest body (FORMAT.md, "Manifest")."""

    def __init__(self, body: Mapping[str, Any]):
        self._body = dict(body)

    # -- reading a version -----------------------------------------------------------------

    def __getitem__(self, key: str) -> Any:
        return self._body[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self._body)

    def __len__(self) -> int:
        return len(self._body)

    @property
    def segments(self) -> list[dict[str, Any]]:
        """The sealed segments' entries, in seq order."""
        return self._body["segments"]

    @cached_property
    def sealed(self) -> tuple[SealedSegment, ...]:
        """The sealed segments' entries as objects (built once per version)."""
        return tuple(SealedSegment.from_info(info) for info in self.segments)

    @property
    def first_seq(self) -> int:
        """Sequence number of the store's first record (> 0 once retention dropped segments)."""
        return self._body.get("first_seq", 0)

    @property
    def end_seq(self) -> int:
        """One past the last sealed record (first_seq when nothing is sealed)."""
        return self.segments[-1]["end_seq"] if self.segments else self.first_seq

    @property
    def dropped(self) -> dict[str, Any]:
        """What retention dropped so far: {"segments": n, "streams": {name: stats}}."""
        return self._body.get("dropped", {"segments": 0, "streams": {}})

    @property
    def store_id(self) -> str:
        return self._body["store_id"]

    @property
    def format_version(self) -> int:
        return self._body["format_version"]

    def named_files(self) -> set[str]:
        """Segment and index file names of every generation this version names."""
        return {name for info in self.segments
                for name in (segment_name(info["first_seq"], info.get("gen", 0)),
                             index_name(info["first_seq"], info.get("gen", 0)))}  # fmt: skip

    # -- the next version ------------------------------------------------------------------

    @classmethod
    def new(cls, codec_config: dict[str, Any]) -> Manifest:
        """The first version of a new store."""
        return cls({"format_version": FORMAT_VERSION, "store_id": uuid.uuid4().hex,
                    "created_ns": time.time_ns(), "codec": codec_config, "segments": []})  # fmt: skip

    @property
    def checkpoint(self) -> dict[str, int]:
        """What a clean close proved durable of the active segment: {"first_seq", "synced",
        "next_seq"} and, when it knew it, "xxh3": the digest of the segment's first `synced`
        bytes and its checkpoint index (FORMAT.md, "Proof of what was synced"); {} when none."""
        return self._body.get("checkpoint", {})

    def damage(self) -> list[tuple[dict[str, Any], dict[str, Any]]]:
        """(segment entry, damage entry) for every damaged stretch not yet discarded."""
        return [(info, d) for info in self.segments for d in info.get("damaged", ())]

    def _next(self, **changes: Any) -> Manifest:
        # Whatever this version writes may hold record version 2 and the keys of format
        # version 3, which an older reader would misread: it must refuse the store.
        return Manifest(dict(self._body, format_version=FORMAT_VERSION, generation=self.generation + 1, **changes))

    @property
    def generation(self) -> int:
        """Counts the manifest's versions; segment files state the one they were made under,
        so a manifest rolled back to an older copy is detected (FORMAT.md, "MANIFEST")."""
        return self._body.get("generation", 0)

    def with_sealed(self, info: dict[str, Any]) -> Manifest:
        """A segment sealed: appended to the list."""
        return self._next(segments=[*self.segments, info])

    def with_checkpoint(self, first_seq: int, synced: int, next_seq: int, xxh3: int | None = None) -> Manifest:
        """A clean close: the active segment is durable up to `synced` bytes, `next_seq`;
        `xxh3` (when known) the digest that lets the writer's next open trust its index."""
        mark = {"first_seq": first_seq, "synced": synced, "next_seq": next_seq}
        return self._next(checkpoint=mark if xxh3 is None else dict(mark, xxh3=xxh3))

    @property
    def quarantine(self) -> list[str]:
        """Files in the store's `quarantine/` directory: bytes cut from the log, kept until
        `fsck --repair --discard-damaged` drops them."""
        return self._body.get("quarantine", [])

    def with_quarantined(self, name: str) -> Manifest:
        return self._next(quarantine=sorted({*self.quarantine, name}))

    def with_damage(self, first_seq: int, damaged: list[dict[str, Any]], streams: dict[str, Any],
                    aged: dict[str, int], size: int | None = None) -> Manifest:  # fmt: skip
        """The sealed segment at `first_seq` holds these damaged stretches; `streams` and
        `aged` count only its intact records; `size`, when given, is its file's size now
        (a segment cut short since sealing, the cut among the stretches)."""
        segments = [dict(info, damaged=damaged, streams=streams, aged=aged, size=info["size"] if size is None else size)
                    if info["first_seq"] == first_seq else info for info in self.segments]  # fmt: skip
        return self._next(segments=segments)

    def with_damage_discarded(self) -> Manifest:
        """Damage dropped on request: each stretch moves from `damaged` to `discarded`, a
        record of what was lost that no longer stops reads."""
        segments = []
        for info in self.segments:
            info = dict(info)
            lost = info.pop("damaged", [])
            if lost:
                info["discarded"] = [*info.get("discarded", []), *lost]
            segments.append(info)
        return self._next(segments=segments, quarantine=[])

    def with_replaced(self, infos: Mapping[int, dict[str, Any]]) -> Manifest:
        """Segments rewritten as new generations: `infos` by first_seq."""
        segments = [infos.get(info["first_seq"], info) for info in self.segments]
        return self._next(segments=segments)

    def without_oldest(self, carried: Collection[str] = ()) -> Manifest:
        """Retention: the oldest sealed segment dropped, its statistics added to `dropped`
        but those of the streams `carried` (their windows were put again: none is lost)."""
        oldest = self.segments[0]
        before = self.dropped
        streams = {k: dict(v) for k, v in before["streams"].items()}
        merge_stream_stats(streams, {k: v for k, v in oldest["streams"].items() if k not in carried})
        return self._next(first_seq=oldest["end_seq"], segments=self.segments[1:],
                          dropped={"segments": before["segments"] + 1, "streams": streams})

    # -- on disk ---------------------------------------------------------------------------

    def commit(self, fs: FileSystem, path: str) -> None:
        """Make this version the store's: one atomic replace of the MANIFEST file."""
        fs.write_file_atomic(path, pack_manifest(self._body))

    def encoded_size(self) -> int:
        """Bytes this version takes as a MANIFEST file."""
        return len(pack_manifest(self._body))

    @staticmethod
    def read_bytes(fs: FileSystem, path: str) -> bytes:
        """The MANIFEST file's bytes, its size checked against the format's limit first."""
        try:
            return fs.read_file(path, limit=manifest_size_limit())
        except FileTooLargeError as err:
            raise CorruptionError(f"{path} is damaged: {Reason.BAD_LENGTH}: {err.strerror}", path=path,
                                  offset=0, reason=Reason.BAD_LENGTH) from None  # fmt: skip

    @classmethod
    def load(cls, fs: FileSystem, path: str) -> tuple[Manifest, bytes]:
        """Read and check the MANIFEST file (every field: manifest_check); the version and
        the bytes it was read from."""
        raw = cls.read_bytes(fs, path)
        try:
            body = unpack_manifest(raw)
            version = body_version(body)
            if version in FORMAT_VERSIONS:  # a newer version may hold what this one does not know
                check_body(body)
        except RecordError as err:
            raise CorruptionError(f"{path} is damaged: {err}; `cclog fsck --repair` rebuilds it from the segment "
                                  "files (the damaged one kept in quarantine/)", path=path, offset=0,
                                  reason=err.reason) from err  # fmt: skip
        if version not in FORMAT_VERSIONS:
            raise StoreError(f"{path}: field format_version is {version!r}, which this cclogfs cannot read "
                             f"(it reads versions {', '.join(map(str, FORMAT_VERSIONS))}); use a newer cclogfs")  # fmt: skip
        return cls(body), raw
