"""Helpers for tests that build stores and damage their files on purpose.

Every test that pokes bytes of a store goes through these, so an offset or a mask means the
same thing everywhere: `flip` XORs one byte, `zero` overwrites a range, `patch_header`
rewrites fields of a record's fixed header and re-seals its CRC (damage a checksum cannot
see), `record_at` finds a record through the store's own index.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import cclogfs
from cclogfs.store.format import RECORD_FIXED, crc32c, segment_name

SEG = segment_name(0)  # the first segment of a new store
HEADER_FIELDS = ["magic", "kind", "version", "flags", "header_len", "seq", "start", "end", "count",
                 "codec", "name_len", "config_len", "meta_len", "raw_len", "enc_len", "xxh3"]  # fmt: skip


def make_store(path, n: int = 4, **opts) -> list[tuple[int, int, int]]:
    """A store with `n` windows of 20 messages on "/a" (put i spans [10 i, 10 i + 19] ns);
    returns (seq, offset, length) of each record."""
    with cclogfs.open_store(path, create=True, **opts) as store:
        for i in range(n):
            store.put_window("/a", [(i * 10 + k, json.dumps({"i": i, "k": k})) for k in range(20)])
        return [(w.seq, w.offset, w.stored_bytes) for w in store.query()]


def seqs(store) -> list[int]:
    return [w.seq for w in store.query()]


def record_at(path, seq: int) -> tuple[Path, int, int]:
    """(segment file, offset, length) of the record `seq` of the store at `path`."""
    with cclogfs.open_store(path, readonly=True) as store:
        (w,) = [w for w in store.query() if w.seq == seq]
        return Path(w.segment_path), w.offset, w.stored_bytes


def flip(path, offset: int, mask: int = 0x40) -> None:
    """XOR the byte at `offset` (negative: from the end) of the file with `mask`."""
    data = bytearray(Path(path).read_bytes())
    data[offset] ^= mask
    Path(path).write_bytes(bytes(data))


def zero(path, start: int, end: int) -> None:
    """Overwrite bytes [start, end) of the file with zeros."""
    data = bytearray(Path(path).read_bytes())
    data[start:end] = bytes(end - start)
    Path(path).write_bytes(bytes(data))


def cut(path, size: int) -> None:
    """Truncate the file to `size` bytes."""
    with open(path, "r+b") as f:
        f.truncate(size)


def append(path, data: bytes) -> None:
    with open(path, "ab") as f:
        f.write(data)


def patch_header(path, offset: int, **fields) -> None:
    """Rewrite fixed-header fields (names in HEADER_FIELDS) of the record at `offset`, then
    fix its header CRC."""
    data = bytearray(Path(path).read_bytes())
    values = dict(zip(HEADER_FIELDS, RECORD_FIXED.unpack_from(data, offset)))
    values.update(fields)
    RECORD_FIXED.pack_into(data, offset, *values.values())
    header_len = values["header_len"]
    struct.pack_into("<I", data, offset + header_len - 4, crc32c(bytes(data[offset : offset + header_len - 4])))
    Path(path).write_bytes(bytes(data))


def unseal(path, keep: int) -> None:
    """Rewrite the store's MANIFEST to name only its first `keep` sealed segments: the later
    ones become the unsealed tail, as after a crash while sealing."""
    from cclogfs.store.format import MANIFEST, pack_manifest, unpack_manifest

    manifest = Path(path) / MANIFEST
    body = unpack_manifest(manifest.read_bytes())
    body["segments"] = body["segments"][:keep]
    manifest.write_bytes(pack_manifest(body))
    for idx in Path(path).glob("*.idx"):  # a tail segment has no index yet
        if not any(idx.name == f"{s['first_seq']:020d}.idx" for s in body["segments"]):
            idx.unlink()


def segment_files(path) -> list[Path]:
    return sorted(Path(path).glob("*.seg"))


def drop_checkpoint(path) -> None:
    """Rewrite the store's MANIFEST without the checkpoint of its last clean close: the
    state a crash after the last put leaves, whose unsynced tail recovery may cut."""
    from cclogfs.store.format import MANIFEST, pack_manifest, unpack_manifest

    manifest = Path(path) / MANIFEST
    body = unpack_manifest(manifest.read_bytes())
    body.pop("checkpoint", None)
    manifest.write_bytes(pack_manifest(body))


def forge_index_offsets(store_dir, seg_name: str) -> None:
    """Rewrite a sealed segment's index with a valid checksum but its entries' offsets and
    lengths reversed: every entry then points at another record (a forged or stale index)."""
    from cclogfs.store.index import SegmentIndex

    seg = Path(store_dir) / seg_name
    idx = seg.with_suffix(".idx")
    size = seg.stat().st_size
    index = SegmentIndex.decode(idx.read_bytes(), 0, size)
    e = index.entries
    rows = [(index.names[x[0]], *x[1:5], *y[5:7], x[7]) for x, y in zip(e, e[::-1])]  # offset, length of another
    idx.write_bytes(SegmentIndex.build(rows).encode(0, size))
