"""The manifest as versions: each change builds a new one; commit is one atomic replace."""

import pytest

from cclogfs.errors import CorruptionError, StoreError
from cclogfs.store.format import FORMAT_VERSION, MANIFEST, Reason, pack_manifest
from cclogfs.store.fs import FileSystem
from cclogfs.store.manifest import Manifest, SealedSegment
from helpers import flip


def info(first, end, gen=0, **streams):
    out = {"first_seq": first, "end_seq": end, "size": 100 * (end - first),
           "streams": {k: {"windows": v, "messages": v, "start_ns": first, "end_ns": end, "raw_bytes": v,
                           "stored_bytes": v} for k, v in streams.items()}}  # fmt: skip
    if gen:
        out["gen"] = gen
    return out


def test_a_new_manifest():
    m = Manifest.new({"id": "none"})
    assert m.format_version == FORMAT_VERSION and len(m.store_id) == 32 and m["codec"] == {"id": "none"}
    assert m.segments == [] and m.first_seq == 0 and m.end_seq == 0
    assert m.dropped == {"segments": 0, "streams": {}}


def test_versions_are_built_never_changed():
    m0 = Manifest.new({"id": "none"})
    m1 = m0.with_sealed(info(0, 10, a=3))
    m2 = m1.with_sealed(info(10, 20, a=1, b=2))
    assert m0.segments == [] and len(m1.segments) == 1 and m2.end_seq == 20
    assert m2.format_version == FORMAT_VERSION  # sealing is not compaction
    m3 = m2.with_replaced({10: info(10, 20, gen=1, a=1)})
    assert m3.format_version == FORMAT_VERSION and m3.segments[1]["gen"] == 1
    assert m2.segments[1].get("gen") is None and m3.segments[0] is m2.segments[0]
    m4 = m3.without_oldest()
    assert m4.first_seq == 10 and [s["first_seq"] for s in m4.segments] == [10]
    assert m4.dropped == {"segments": 1, "streams": {"a": info(0, 10, a=3)["streams"]["a"]}}
    m5 = m4.without_oldest()
    assert m5.first_seq == 20 == m5.end_seq and m5.dropped["segments"] == 2
    assert m5.dropped["streams"]["a"]["windows"] == 4 and m4.dropped["streams"]["a"]["windows"] == 3


def test_sealed_segments_and_named_files():
    m = Manifest.new({"id": "none"}).with_sealed(info(0, 10, a=3)).with_replaced({0: dict(info(0, 10, gen=2, a=3),
                                                                                          aged={"a": 1})})  # fmt: skip
    (s,) = m.sealed
    assert s == SealedSegment(0, 10, 1000, 2, info(0, 10, a=3)["streams"], {"a": 1})
    assert m.named_files() == {"00000000000000000000-2.seg", "00000000000000000000-2.idx"}


def test_commit_and_load(tmp_path):
    fs = FileSystem()
    path = str(tmp_path / MANIFEST)
    m = Manifest.new({"id": "zstd"}).with_sealed(info(0, 3, a=1))
    m.commit(fs, path)
    back, raw = Manifest.load(fs, path)
    assert dict(back) == dict(m) and raw == (tmp_path / MANIFEST).read_bytes()
    assert [p.name for p in tmp_path.iterdir()] == [MANIFEST]  # the temporary file is gone


def test_load_names_damage_and_unknown_versions(tmp_path):
    fs = FileSystem()
    path = tmp_path / MANIFEST
    Manifest.new({"id": "none"}).commit(fs, str(path))
    flip(path, 14)
    with pytest.raises(CorruptionError, match="MANIFEST is damaged") as err:
        Manifest.load(fs, str(path))
    assert err.value.reason == Reason.HEADER_CRC
    path.write_bytes(pack_manifest({"format_version": 9, "segments": []}))
    with pytest.raises(StoreError, match="format_version is 9"):
        Manifest.load(fs, str(path))


def test_a_rolled_back_manifest_is_refused_and_nothing_is_deleted(tmp_path):
    # Issue 11, item 7: an older valid MANIFEST after a compaction used to make the writer
    # remove every later segment as 'after a gap'.
    import cclogfs
    from cclogfs.errors import CorruptionError
    from cclogfs.store import Replacement
    from cclogfs.store.format import Reason

    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True, segment_records=3, sync_every_ms=None) as store:
        for i in range(6):
            store.put_window("/a", [(i, str(i))])
        old = (path / "MANIFEST").read_bytes()
        store.rewrite(lambda w: Replacement([(w.start_ns, '"x"')], {}) if w.seq == 1 else None)
        for i in range(6, 14):
            store.put_window("/a", [(i, str(i))])
    (path / "MANIFEST").write_bytes(old)
    before = {p.name: p.read_bytes() for p in path.iterdir()}
    for opts in ({}, {"readonly": True}):
        with pytest.raises(CorruptionError, match="rolled back") as err:
            cclogfs.open_store(path, **opts)
        assert err.value.reason == Reason.ROLLED_BACK
    assert {p.name: p.read_bytes() for p in path.iterdir()} == before
