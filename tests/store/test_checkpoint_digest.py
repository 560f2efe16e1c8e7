"""Issue 14: the writer opens a cleanly closed store without scanning its active segment.
A clean close states in the checkpoint the XXH3-64 of the segment's first `synced` bytes
followed by its checkpoint index; the writer's open hashes those bytes and that index and,
when they still match, takes the records below the checkpoint from the index and scans only
what followed. Any other byte there makes it scan whole and name the damage, as before.

Every test holds the digest to what it claims (`digest_state`): after any step it is
either absent or exactly the hash of those bytes, never stale."""

import json
import shutil
from pathlib import Path

import pytest
import xxhash

import cclogfs
from cclogfs.errors import CorruptionError
from cclogfs.store import recovery, repair_store
from cclogfs.store.format import MANIFEST, SEGMENT_HEADER_SIZE, index_name, pack_manifest, segment_name, unpack_manifest
from cclogfs.store.index import SegmentIndex
from helpers import SEG, flip, make_store

IDX = SEG.replace(".seg", ".idx")


@pytest.fixture
def scans(monkeypatch):
    """Where each scan of a tail segment started: (offset, seq). (Opening also reads the last
    record of the last sealed segment, to check its end: not counted.)"""
    starts = []
    real = recovery.scan

    def spy(seg, *, salvage=False, start=None):
        if seg.sealed_size < 0:
            starts.append(start or (SEGMENT_HEADER_SIZE, seg.first_seq))
        return real(seg, salvage=salvage, start=start)

    monkeypatch.setattr(recovery, "scan", spy)
    return starts


def manifest_body(path) -> dict:
    return unpack_manifest((Path(path) / MANIFEST).read_bytes())


def write_body(path, body: dict) -> None:
    (Path(path) / MANIFEST).write_bytes(pack_manifest(body))


def digest_state(path) -> str:
    """'absent', 'holds' (the XXH3-64 of the active segment's first `synced` bytes then its
    checkpoint index, computed here from the files), 'sealed' (the checkpoint is of a segment
    sealed since, which every open ignores) or 'stale'."""
    body = manifest_body(path)
    mark = body.get("checkpoint", {})
    if "xxh3" not in mark:
        return "absent"
    if mark["first_seq"] < (body["segments"][-1]["end_seq"] if body["segments"] else 0):
        return "sealed"
    seg = Path(path) / segment_name(mark["first_seq"])
    idx = Path(path) / index_name(mark["first_seq"])
    data = seg.read_bytes()
    if len(data) < mark["synced"]:
        return "stale"
    ok = xxhash.xxh3_64_intdigest(data[: mark["synced"]] + idx.read_bytes()) == mark["xxh3"]
    return "holds" if ok else "stale"


def contents(path):
    with cclogfs.open_store(path, readonly=True, verify=True) as store:
        return [(w.seq, w.name, w.start_ns, w.end_ns, list(w.messages())) for w in store.query()]


def put(store, i: int, name: str = "/b") -> None:
    store.put_window(name, [(i * 10 + k, json.dumps({"i": i, "k": k})) for k in range(5)])


def test_the_writer_opens_a_clean_close_scanning_only_past_the_checkpoint(tmp_path, scans):
    make_store(tmp_path / "s", n=6)
    assert digest_state(tmp_path / "s") == "holds"
    mark = manifest_body(tmp_path / "s")["checkpoint"]
    before = contents(tmp_path / "s")
    scans.clear()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert scans == [(mark["synced"], 6)]  # a scan of nothing: the file ends at the checkpoint
        assert store.recovery.clean and store.damage() == []
        assert [w.seq for w in store.query()] == list(range(6))
        assert [w.seq for w in store.query("/a", 20, 30)] == [1, 2, 3]
        assert store.streams()["/a"]["windows"] == 6
        put(store, 6)  # appended after the trusted records, hashed on from the checkpoint's state
    assert digest_state(tmp_path / "s") == "holds"
    assert contents(tmp_path / "s")[:6] == before
    scans.clear()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert scans == [(manifest_body(tmp_path / "s")["checkpoint"]["synced"], 7)]
        assert [w.seq for w in store.query()] == list(range(7))


@pytest.mark.parametrize("where", ["segment header", "first record", "payload", "last byte before synced"])
def test_a_byte_changed_below_the_checkpoint_is_named_though_the_index_still_matches(tmp_path, scans, where):
    # The index and the checkpoint are untouched and agree with each other: only the hash of
    # the bytes tells the writer that one of them changed. Trusting the index would miss it.
    recs = make_store(tmp_path / "s", n=5)
    synced = manifest_body(tmp_path / "s")["checkpoint"]["synced"]
    _seq, off, length = recs[2]
    at = {"segment header": 8, "first record": recs[0][1] + 20, "payload": off + length - 5,
          "last byte before synced": synced - 1}[where]  # fmt: skip
    flip(tmp_path / "s" / SEG, at)
    scans.clear()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert scans[0] == (SEGMENT_HEADER_SIZE, 0)  # scanned whole
        assert store.damage() != []  # named, and the segment sealed with it
        put(store, 9)
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert store.damage() != []
    assert digest_state(tmp_path / "s") == "holds"  # of the segment begun after the sealed one


def test_damaged_bytes_with_an_index_rebuilt_to_match_them_are_named(tmp_path, scans):
    # A bad copy of the segment and its index made to agree (checksum, sizes, offsets): the
    # digest also covers the bytes below the checkpoint, so the writer still scans.
    recs = make_store(tmp_path / "s", n=5)
    _seq, off, length = recs[1]
    flip(tmp_path / "s" / SEG, off + length - 3)
    mark = manifest_body(tmp_path / "s")["checkpoint"]
    old = SegmentIndex.decode((tmp_path / "s" / IDX).read_bytes(), 0, mark["synced"])
    (tmp_path / "s" / IDX).write_bytes(SegmentIndex.build(old.rows()).encode(0, mark["synced"]))
    scans.clear()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert scans[0] == (SEGMENT_HEADER_SIZE, 0)
        assert [(d["first_seq"], d["end_seq"]) for d in store.damage()] == [(1, 2)]


def test_another_index_with_a_valid_checksum_is_not_trusted(tmp_path, scans):
    # Same size, seqs and offsets, but another stream name: the index is hashed with the
    # bytes, so the writer scans, and its seal states the segment's real streams.
    make_store(tmp_path / "s", n=4)
    mark = manifest_body(tmp_path / "s")["checkpoint"]
    old = SegmentIndex.decode((tmp_path / "s" / IDX).read_bytes(), 0, mark["synced"])
    rows = [("/forged", *r[1:]) for r in old.rows()]
    (tmp_path / "s" / IDX).write_bytes(SegmentIndex.build(rows).encode(0, mark["synced"]))
    scans.clear()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert scans == [(SEGMENT_HEADER_SIZE, 0)]
        assert list(store.streams()) == ["/a"]
        store.seal()
        assert list(store.sealed_segments()[0].streams) == ["/a"]


def test_a_digest_that_does_not_match_makes_the_writer_scan_and_close_writes_it_again(tmp_path, scans):
    make_store(tmp_path / "s", n=4)
    body = manifest_body(tmp_path / "s")
    body["checkpoint"]["xxh3"] ^= 1
    write_body(tmp_path / "s", body)
    scans.clear()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert scans == [(SEGMENT_HEADER_SIZE, 0)] and store.damage() == []
        put(store, 4)
    assert digest_state(tmp_path / "s") == "holds"


def test_a_manifest_without_the_digest_is_scanned_as_before(tmp_path, scans):
    # What an older version wrote: opened by a scan; the next close that wrote adds it.
    make_store(tmp_path / "s", n=4)
    body = manifest_body(tmp_path / "s")
    del body["checkpoint"]["xxh3"]
    write_body(tmp_path / "s", body)
    scans.clear()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert scans == [(SEGMENT_HEADER_SIZE, 0)]
    assert digest_state(tmp_path / "s") == "absent"  # nothing written: the manifest as it was
    with cclogfs.open_store(tmp_path / "s") as store:
        put(store, 4)  # the segment is read back to hash it, once, at this close
    assert digest_state(tmp_path / "s") == "holds"
    scans.clear()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert scans == [(manifest_body(tmp_path / "s")["checkpoint"]["synced"], 5)]


@pytest.mark.parametrize("value", [-1, 1 << 64, "0", True, 1.5])
def test_a_digest_of_the_wrong_type_is_a_damaged_manifest(tmp_path, value):
    make_store(tmp_path / "s", n=2)
    body = manifest_body(tmp_path / "s")
    body["checkpoint"]["xxh3"] = value
    write_body(tmp_path / "s", body)
    with pytest.raises(CorruptionError, match="checkpoint.xxh3"):
        cclogfs.open_store(tmp_path / "s")


def test_after_a_crash_past_the_checkpoint_the_writer_scans_only_the_tail(tmp_path, scans):
    make_store(tmp_path / "s", n=4)
    mark = manifest_body(tmp_path / "s")["checkpoint"]
    store = cclogfs.open_store(tmp_path / "s", sync_every_ms=None)
    for i in range(4, 7):
        put(store, i)
    store.sync()
    shutil.copytree(tmp_path / "s", tmp_path / "crashed")  # the disk as a crash now leaves it
    store.close()
    with open(tmp_path / "crashed" / SEG, "ab") as f:  # and a torn record past the last sync
        f.write(b"CCLR" + bytes(40))
    assert digest_state(tmp_path / "crashed") == "holds"  # the old checkpoint: its bytes unchanged
    scans.clear()
    with cclogfs.open_store(tmp_path / "crashed") as store:
        assert scans == [(mark["synced"], 4)]
        assert [p.reason for p in store.recovery.problems] != []  # the torn record cut
        assert [w.seq for w in store.query()] == list(range(7))
        put(store, 7)  # hashed on from the end recovery kept, not the torn bytes it cut
    assert digest_state(tmp_path / "crashed") == "holds"
    assert contents(tmp_path / "crashed")[:7] == contents(tmp_path / "s")
    scans.clear()
    with cclogfs.open_store(tmp_path / "crashed") as store:
        assert scans == [(manifest_body(tmp_path / "crashed")["checkpoint"]["synced"], 8)]


def test_a_segment_roll_keeps_the_digest_exact(tmp_path, scans):
    make_store(tmp_path / "s", n=5, segment_records=3)  # rolled at 3: the active one holds 3, 4
    mark = manifest_body(tmp_path / "s")["checkpoint"]
    assert mark["first_seq"] == 3 and digest_state(tmp_path / "s") == "holds"
    with cclogfs.open_store(tmp_path / "s", segment_records=3) as store:
        put(store, 5)  # fills it: sealed, a new active segment holding nothing
    assert manifest_body(tmp_path / "s")["checkpoint"]["first_seq"] == 6
    assert digest_state(tmp_path / "s") == "absent"  # only its header: nothing to trust
    with cclogfs.open_store(tmp_path / "s", segment_records=3) as store:
        put(store, 6)
    assert digest_state(tmp_path / "s") == "holds"
    scans.clear()
    with cclogfs.open_store(tmp_path / "s", segment_records=3) as store:
        assert scans == [(manifest_body(tmp_path / "s")["checkpoint"]["synced"], 7)]
        assert [w.seq for w in store.query()] == list(range(7))


def test_compaction_and_retention_leave_the_active_segments_digest_exact(tmp_path, scans):
    from cclogfs.store import Replacement

    make_store(tmp_path / "s", n=7, segment_records=3)
    with cclogfs.open_store(tmp_path / "s", segment_records=3) as store:
        store.rewrite(lambda w: Replacement(list(w.messages())[::2], w.meta))
        store.drop_oldest()
    assert digest_state(tmp_path / "s") == "holds"
    want = contents(tmp_path / "s")
    scans.clear()
    with cclogfs.open_store(tmp_path / "s", segment_records=3) as store:
        assert scans == [(manifest_body(tmp_path / "s")["checkpoint"]["synced"], 7)]
        assert [w.seq for w in store.query()] == [3, 4, 5, 6]
    assert contents(tmp_path / "s") == want


def test_repair_leaves_the_digest_exact_or_absent(tmp_path):
    recs = make_store(tmp_path / "s", n=5)
    _seq, off, length = recs[3]
    flip(tmp_path / "s" / SEG, off + length - 5)
    assert repair_store(str(tmp_path / "s")).exit_code == 4  # damage named, left for --discard-damaged
    # The damaged segment was sealed with its damage named; its checkpoint is dead data now,
    # and the new active segment, never written, has none.
    assert digest_state(tmp_path / "s") == "sealed"
    with cclogfs.open_store(tmp_path / "s") as store:
        assert {(d["first_seq"], d["end_seq"]) for d in store.damage()} == {(3, 4)}
        put(store, 5)
    assert digest_state(tmp_path / "s") == "holds"
    assert repair_store(str(tmp_path / "s"), discard_damaged=True).exit_code == 1
    assert digest_state(tmp_path / "s") == "holds"
    with cclogfs.open_store(tmp_path / "s") as store:
        assert store.damage() == [] and [w.seq for w in store.query()] == [0, 1, 2, 4, 5]
