"""Bit rot at the parsers, fast enough for 100,000 flips in CI (issue 16, "Bit rot and
forgery"). Every file kind of a store (segments, indexes, MANIFEST with its checkpoint,
LOCK, a side file) is damaged in memory, by one flipped bit, a burst of random bytes or a
zeroed 512-byte sector, and parsed as the store parses it: the MANIFEST checks, the index
decoder, the segment scan (every record decoded), the side-file salvage search. What must
hold: no exception but the project's errors (no traceback), and no changed message: a
record that passes its checks decodes to exactly what was put, and an index or manifest
that passes is exactly the one written.

    python -m bench bitflip_fast [--flips 1000000] [--seed 1]

bench/bitflip.py runs the slower end-to-end trials (fsck, reopen, repair, nothing lost).
"""

from __future__ import annotations

import argparse
import json
import random
import tempfile
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import cclogfs
from cclogfs.codecs import codec_for_record
from cclogfs.errors import CclogError
from cclogfs.store.format import (
    LOCK,
    MANIFEST,
    RESERVE,
    RecordError,
    parse_seq_name,
    unpack_manifest,
    unpack_segment_header,
)
from cclogfs.store.index import SegmentIndex
from cclogfs.store.manifest_check import body_version, check_body
from cclogfs.store.records import BytesAt, intact_in, records

from bench._util import BytesFile

SIDE = "00000000000000000000.seg.tail-32"
MODES = ("bit", "burst", "sector")


@dataclass
class Oracle:
    """A store's files and what each must parse to."""

    files: dict[str, bytes]
    windows: dict[int, tuple[str, list]]  # seq -> (stream, messages)
    body: dict
    indexes: dict[str, tuple[list, bytes]]  # .idx name -> (names, entries bytes)
    sizes: dict[str, int]  # .idx name -> its segment's size
    starts: dict[str, list[tuple[int, int]]]  # .seg name -> (offset, seq) of each record


def build(root: Path, windows: int, segment_records: int) -> Oracle:
    path = root / f"store-{windows}"
    with cclogfs.open_store(path, create=True, segment_records=segment_records, sync_every_ms=None,
                            stream_codecs={"/z": "zstd", "/n": "none", "/l": "lzma"}) as store:  # fmt: skip
        for i in range(windows):
            name = ("/odom", "/z", "/n", "/l")[i % 4]
            store.put_window(name, [(i * 100 + k, json.dumps({"i": i, "x": k * 0.25, "s": "abc"[k % 3]}))
                                    for k in range(1 + i % 5)], meta={"i": i})  # fmt: skip
        store.sync()
        with cclogfs.open_store(path, readonly=True) as reader:
            seen = {w.seq: (w.name, list(w.messages())) for w in reader.query()}
        # RESERVE is preallocated space nothing ever reads (FORMAT.md, "Reserve"): no parser to damage.
        files = {p.name: p.read_bytes() for p in path.iterdir() if p.is_file() and p.name != RESERVE}
    first_seg = files["00000000000000000000.seg"]
    files[SIDE] = first_seg[32:][:2048]  # what recovery keeps when it cuts at the first record
    files[LOCK] = b'{"pid": 1234, "host": "robot"}'
    indexes, sizes = {}, {}
    for name, data in files.items():
        if name.endswith(".idx"):
            seg = files[name[:-4] + ".seg"]
            sizes[name] = len(seg)
            idx = SegmentIndex.decode(data, parse_seq_name(name)[0], len(seg))
            indexes[name] = (idx.names, list(idx.entries))
    starts = {}
    for name, data in files.items():
        if name.endswith(".seg"):
            starts[name] = [(r.offset, r.header.seq) for r in records(BytesAt(data), 32, len(data),
                                                                         parse_seq_name(name)[0])]  # fmt: skip
    return Oracle(files, seen, unpack_manifest(files[MANIFEST]), indexes, sizes, starts)


def _decoded(header, payload) -> tuple[str, list]:
    stamps, texts = codec_for_record(header.config).decode(payload, count=header.count, raw_len=header.raw_len)
    return header.name, list(zip(stamps, texts))


def changed_by(oracle: Oracle, name: str, data: bytes, lo: int = 0) -> int:
    """Parse `data` as file `name` is parsed; how many things it yields differ from the
    original (must be 0). Only the project's errors may be raised, and are caught here."""
    try:
        if name == MANIFEST:
            body = unpack_manifest(data)
            body_version(body)
            check_body(body)
            return int(body != oracle.body)
        if name.endswith(".idx"):
            idx = SegmentIndex.decode(data, parse_seq_name(name)[0], oracle.sizes[name])
            return int((idx.names, list(idx.entries)) != oracle.indexes[name])
        if name == LOCK:
            data.decode(errors="replace").strip()
            return 0
        if name == SIDE:
            return sum(_record_changed(oracle, h, p) for _o, h, p in intact_in(BytesFile(data), 0, 0, len(data)))
        return _segment_changed(oracle, name, data, lo)
    except (CclogError, RecordError):
        return 0


def _segment_changed(oracle: Oracle, name: str, data: bytes, lo: int) -> int:
    """The scan, from the last record that starts at or before the first damaged byte
    `lo` (the records before it are the original bytes, so they parse as before)."""
    unpack_segment_header(data)
    start, seq = 32, parse_seq_name(name)[0]
    for offset, rec_seq in oracle.starts[name]:
        if offset > lo:
            break
        start, seq = offset, rec_seq
    bad = 0
    try:
        for rec in records(BytesAt(data), start, len(data), seq):
            if rec.skip is None:
                bad += _record_changed(oracle, rec.header, rec.payload)
    except RecordError:
        pass
    return bad


def _record_changed(oracle: Oracle, header, payload) -> int:
    try:
        return int(_decoded(header, payload) != oracle.windows.get(header.seq))
    except CclogError:
        return 0


def damage(data: bytes, mode: str, rng: random.Random) -> tuple[bytes, int]:
    """The damaged bytes (same length) and the first offset damaged."""
    out = bytearray(data)
    if mode == "bit":
        lo = rng.randrange(len(out))
        out[lo] ^= 1 << rng.randrange(8)
    elif mode == "burst":
        lo, n = rng.randrange(len(out)), rng.randint(2, 64)
        out[lo : lo + n] = rng.randbytes(n)[: len(out) - lo]
    else:
        lo = rng.randrange(max(1, -(-len(out) // 512))) * 512
        out[lo : lo + 512] = bytes(len(out[lo : lo + 512]))
    return bytes(out), lo


def every_bit(oracle: Oracle) -> Counter:
    """Flip each bit of each file once."""
    totals: Counter = Counter()
    for name, data in oracle.files.items():
        buf = bytearray(data)
        for pos in range(len(buf)):
            for bit in range(8):
                buf[pos] ^= 1 << bit
                totals["changed"] += changed_by(oracle, name, bytes(buf), pos)
                buf[pos] ^= 1 << bit
                totals["flips"] += 1
    return totals


def random_damage(oracle: Oracle, n: int, rng: random.Random) -> Counter:
    """`n` random damages, spread over file kinds and modes."""
    totals: Counter = Counter()
    names = sorted(oracle.files)
    for i in range(n):
        name, mode = names[i % len(names)], MODES[(i // len(names)) % len(MODES)]
        changed = changed_by(oracle, name, *damage(oracle.files[name], mode, rng))
        totals["changed"] += changed
        totals[mode] += 1
        totals[_kind(name)] += 1
    return totals


def _kind(name: str) -> str:
    if name in (MANIFEST, LOCK, SIDE):
        return {MANIFEST: "MANIFEST", LOCK: "LOCK", SIDE: "side file"}[name]
    return "index" if name.endswith(".idx") else "segment"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--flips", type=int, default=1_000_000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        small, large = build(Path(tmp), 12, 4), build(Path(tmp), 400, 64)
    t = time.perf_counter()
    out = {"every bit of the small store": dict(every_bit(small))}
    t_small = time.perf_counter() - t
    t = time.perf_counter()
    out["random damage of the larger store"] = dict(random_damage(large, args.flips, random.Random(args.seed)))
    t_large = time.perf_counter() - t
    out["per second"] = round(args.flips / t_large)
    out["seconds"] = round(t_small + t_large, 1)
    from ._util import save_json

    print(json.dumps(out, indent=1))
    print(f"saved {save_json('bitflip_fast', out)}")
    changed = sum(v.get("changed", 0) for v in out.values() if isinstance(v, dict))
    return 1 if changed else 0
