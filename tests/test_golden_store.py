"""The committed stores of format versions 1 and 2 must read the same forever."""

import json
import shutil
from pathlib import Path

import cclogfs
from cclogfs.codecs import CodecId
from cclogfs.store.format import pack_record

GOLDEN = Path(__file__).parent / "golden"


def test_golden_store_reads_back(tmp_path):
    expected = json.loads((GOLDEN / "store_v1.expected.json").read_text())
    shutil.copytree(GOLDEN / "store_v1", tmp_path / "s")
    for opts in ({"readonly": True}, {}):
        with cclogfs.open_store(tmp_path / "s", **opts) as store:
            assert store.recovery.clean
            got = sorted(store.query(), key=lambda w: w.seq)
            assert [
                {"seq": w.seq, "name": w.name, "meta": w.meta, "messages": [list(m) for m in w.messages()]}
                for w in got
            ] == expected
            assert len(store.sealed) >= 1  # the golden store has sealed segments and an index


def test_record_bytes_are_pinned():
    # The "none" record of /tf is stored verbatim: today's encoder must produce the same bytes.
    from cclogfs.codecs import frame

    data = (GOLDEN / "store_v1" / "00000000000000000001.seg").read_bytes()
    texts = [b'{"a" :1.0, "b":[ ]}', b' "\\u00e9" ']
    raw = frame([1_000_000_000, 1_000_000_001], [t.decode() for t in texts])
    record = pack_record(seq=2, start_ns=1_000_000_000, end_ns=1_000_000_001, count=2, codec=CodecId.NONE,
                         name=b"/tf", config=b'{"id":"none"}', meta=b"{}", raw_len=len(raw), payload=raw)  # fmt: skip
    assert record in data


def test_golden_store_v2_reads_back(tmp_path):
    # Compacted: the log starts at seq 2, generations 1 and 2, an AGED record, an active segment.
    from cclogfs.store import check_store

    expected = json.loads((GOLDEN / "store_v2.expected.json").read_text())
    shutil.copytree(GOLDEN / "store_v2", tmp_path / "s")
    before = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()}
    for opts in ({"readonly": True}, {"sync_every_ms": None, "segment_age_s": 1e12}):
        with cclogfs.open_store(tmp_path / "s", **opts) as store:
            assert store.recovery.clean and not store.recovery.leftovers
            assert store.manifest["format_version"] == 2
            assert store.first_seq == expected["first_seq"] == 2
            assert store.dropped() == expected["dropped"]
            assert {str(s.first_seq): s.gen for s in store.sealed} == expected["gens"]
            got = sorted(store.query(), key=lambda w: w.seq)
            assert [
                {"seq": w.seq, "name": w.name, "meta": w.meta, "flags": w.flags, "aged": w.aged,
                 "codec": w.codec_config, "messages": [list(m) for m in w.messages()]}
                for w in got
            ] == expected["windows"]  # fmt: skip
            assert store.streams()["/tf"]["aged"] == 1 and store.streams()["/odom"]["aged"] == 0
    after = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir() if p.name not in ("LOCK", "RESERVE")}
    assert after == before  # opening it as the writer changed nothing
    report = check_store(str(tmp_path / "s"), deep=True)
    assert not report.findings and report.aged == 1 and report.decoded == len(expected["windows"])


def test_aged_record_bytes_are_pinned():
    # The AGED record (codec none) of the v2 golden store: today's encoder makes the same bytes.
    from cclogfs.codecs import frame
    from cclogfs.store.format import RecordFlag

    data = (GOLDEN / "store_v2" / "00000000000000000002-1.seg").read_bytes()
    (w,) = [w for w in json.loads((GOLDEN / "store_v2.expected.json").read_text())["windows"] if w["seq"] == 2]
    stamps = [m[0] for m in w["messages"]]
    raw = frame(stamps, [m[1] for m in w["messages"]])
    meta = json.dumps(w["meta"], separators=(",", ":")).encode()
    record = pack_record(seq=2, start_ns=stamps[0], end_ns=stamps[-1], count=len(stamps), codec=CodecId.NONE,
                         name=b"/tf", config=b'{"id":"none"}', meta=meta, raw_len=len(raw), payload=raw,
                         flags=RecordFlag.AGED)  # fmt: skip
    assert record in data


def test_golden_store_v3_reads_back(tmp_path):
    # Version 3: records carry their synced length; the clean close left a checkpoint.
    from cclogfs.store import check_store
    from cclogfs.store.format import unpack_manifest

    expected = json.loads((GOLDEN / "store_v3.expected.json").read_text())
    shutil.copytree(GOLDEN / "store_v3", tmp_path / "s")
    before = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()}
    body = unpack_manifest(before["MANIFEST"])
    assert body["format_version"] == 3 and body["checkpoint"]["first_seq"] == 3
    for opts in ({"readonly": True}, {"sync_every_ms": None, "segment_age_s": 1e12}):
        with cclogfs.open_store(tmp_path / "s", **opts) as store:
            assert store.recovery.clean and not store.damage()
            got = [{"seq": w.seq, "name": w.name, "meta": w.meta, "messages": [list(m) for m in w.messages()]}
                   for w in sorted(store.query(), key=lambda w: w.seq)]  # fmt: skip
            assert got == expected
    after = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir() if p.name not in ("LOCK", "RESERVE")}
    assert after == before
    assert not check_store(str(tmp_path / "s")).findings
    data = before["00000000000000000003.seg"]
    assert data[4:6] == b"\x01\x00" and data[32 + 5] == 2  # segment header 1, record version 2


def test_golden_store_v3_digest_is_opened_by_the_writer_from_its_checkpoint(tmp_path, monkeypatch):
    # The checkpoint's xxh3 pinned: the XXH3-64 of the active segment's first `synced` bytes
    # followed by its checkpoint index file. The writer trusts that index (a scan of nothing
    # past the checkpoint) and changes no file; the windows are store_v3's.
    import xxhash

    from cclogfs.store import check_store, recovery
    from cclogfs.store.format import unpack_manifest

    expected = json.loads((GOLDEN / "store_v3.expected.json").read_text())
    shutil.copytree(GOLDEN / "store_v3_digest", tmp_path / "s")
    before = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()}
    mark = unpack_manifest(before["MANIFEST"])["checkpoint"]
    seg, idx = before["00000000000000000003.seg"], before["00000000000000000003.idx"]
    assert mark["first_seq"] == 3 and mark["synced"] == len(seg)
    assert mark["xxh3"] == xxhash.xxh3_64_intdigest(seg + idx)
    starts = []
    real = recovery.scan
    monkeypatch.setattr(recovery, "scan", lambda s, **kw: starts.append((s.first_seq, kw.get("start"))) or real(s, **kw))
    for opts in ({"readonly": True}, {"sync_every_ms": None, "segment_age_s": 1e12}):
        with cclogfs.open_store(tmp_path / "s", **opts) as store:
            assert store.recovery.clean and not store.damage()
            got = [{"seq": w.seq, "name": w.name, "meta": w.meta, "messages": [list(m) for m in w.messages()]}
                   for w in sorted(store.query(), key=lambda w: w.seq)]  # fmt: skip
            assert got == expected
    assert [s for s in starts if s[0] == 3] == [(3, (len(seg), 5))] * 2  # reader and writer alike
    after = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir() if p.name not in ("LOCK", "RESERVE")}
    assert after == before
    assert not check_store(str(tmp_path / "s")).findings


def test_golden_store_of_split_windows_reads_back(tmp_path):
    # Record flag PART (issue 16): a window over the record limit is stored as parts, every
    # part but the last flagged; the records of earlier versions carry no such flag.
    from cclogfs.store import check_store
    from cclogfs.store.format import RecordFlag, unpack_manifest

    expected = json.loads((GOLDEN / "store_v3_split.expected.json").read_text())
    assert [w["flags"] for w in expected] == [2, 2, 2, 2, 0, 0, 2, 0]
    shutil.copytree(GOLDEN / "store_v3_split", tmp_path / "s")
    before = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir()}
    body = unpack_manifest(before["MANIFEST"])
    assert [(s["first_seq"], s["end_seq"]) for s in body["segments"]] == [(0, 5)]  # all 5 parts, though 4 a segment
    assert body["checkpoint"]["next_seq"] == 8
    for opts in ({"readonly": True}, {"readonly": True, "verify": True}, {"sync_every_ms": None, "segment_age_s": 1e12}):
        with cclogfs.open_store(tmp_path / "s", **opts) as store:
            assert store.recovery.clean and not store.damage()
            got = [{"seq": w.seq, "name": w.name, "meta": w.meta, "flags": w.flags,
                    "messages": [list(m) for m in w.messages()]}
                   for w in sorted(store.query(), key=lambda w: w.seq)]  # fmt: skip
            assert got == expected
    after = {p.name: p.read_bytes() for p in (tmp_path / "s").iterdir() if p.name not in ("LOCK", "RESERVE")}
    assert after == before
    assert not check_store(str(tmp_path / "s"), deep=True).findings
    # The first part of /tf's split window, as today's encoder writes it.
    from cclogfs.codecs import frame

    messages = [m for w in expected if w["seq"] == 6 for m in w["messages"]]
    raw = frame([t for t, _ in messages], [s for _, s in messages])
    record = pack_record(seq=6, start_ns=messages[0][0], end_ns=messages[-1][0], count=len(messages),
                         codec=CodecId.NONE, name=b"/tf", config=b'{"id":"none"}', meta=b'{"window":3}',
                         raw_len=len(raw), payload=raw, flags=RecordFlag.PART,
                         synced=0)  # fmt: skip
    assert record in before["00000000000000000005.seg"]
