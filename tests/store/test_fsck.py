"""fsck: every byte checked against the format and the manifest, nothing changed."""

from pathlib import Path

import cclogfs
from cclogfs.store import check_store
from cclogfs.store.format import MANIFEST, index_name, pack_manifest, segment_name, unpack_manifest
from helpers import SEG, flip, make_store, patch_header, record_at


def store_of(path, n=30):
    """30 windows of 20 messages, sealed every 10: segments 0, 10, 20 and an empty active 30."""
    make_store(path, n=n, segment_records=10, sync_every_bytes=1)
    return path


def files(path):
    return {p.name: p.read_bytes() for p in Path(path).iterdir() if p.name not in ("LOCK", "RESERVE")}


def test_a_clean_store(tmp_path):
    path = store_of(tmp_path / "s")
    with cclogfs.open_store(path, readonly=True) as store:
        store_files = files(path)
    report = check_store(str(path), deep=True)
    assert report.findings == [] and report.errors == []
    assert (report.segments, report.records, report.messages, report.decoded) == (4, 30, 600, 30)
    assert files(path) == store_files  # fsck changes nothing


def test_an_unsealed_tail_is_counted(tmp_path):
    path = tmp_path / "s"
    make_store(path, n=5)  # nothing sealed
    report = check_store(str(path))
    assert report.findings == [] and (report.segments, report.records, report.messages) == (1, 5, 100)


def test_damage_in_a_sealed_segment_is_an_error_and_the_rest_is_framed_by_the_index(tmp_path):
    path = store_of(tmp_path / "s")
    seg, off, length = record_at(path, 3)
    flip(seg, off + length - 2)
    report = check_store(str(path))
    (err,) = report.errors
    assert (err.where, err.what) == (f"{SEG}@{off}", "payload checksum mismatch in a sealed segment")
    assert any("6 records after the damage are intact" in f.what for f in report.findings)


def test_statistics_that_differ_from_the_manifest(tmp_path):
    path = store_of(tmp_path / "s")
    body = unpack_manifest((path / MANIFEST).read_bytes())
    body["segments"][1]["streams"]["/a"]["messages"] += 1
    (path / MANIFEST).write_bytes(pack_manifest(body))
    (err,) = check_store(str(path)).errors
    assert (err.where, err.what) == (segment_name(10), "stream statistics differ from the manifest's")


def test_a_gap_between_sealed_segments(tmp_path):
    path = store_of(tmp_path / "s")
    body = unpack_manifest((path / MANIFEST).read_bytes())
    del body["segments"][1]  # the manifest forgot segment 10
    (path / MANIFEST).write_bytes(pack_manifest(body))
    report = check_store(str(path))
    # Issue 16, item 4: a manifest whose segments do not follow each other is refused on
    # load (naming the field); `fsck --repair` derives it again from the files.
    (err,) = report.errors
    assert "field segments[1].first_seq is 20, expected 10" in err.what


def test_index_findings_are_warnings(tmp_path):
    path = store_of(tmp_path / "s")
    (path / index_name(0)).unlink()
    flip(path / index_name(10), 40)
    (path / index_name(999)).write_bytes(b"x")
    report = check_store(str(path))
    assert report.errors == []
    got = {f.where: f.what for f in report.findings}
    assert got[index_name(0)].startswith("missing") and got[index_name(10)].startswith("damaged")
    assert got[index_name(999)] == "index of a segment that does not exist"


def test_leftovers_of_an_interrupted_compaction_are_warnings(tmp_path):
    path = store_of(tmp_path / "s")
    (path / segment_name(10, 1)).write_bytes(b"half written")
    report = check_store(str(path))
    assert [(f.severity, f.where) for f in report.findings] == [("warning", segment_name(10, 1))]
    assert (path / segment_name(10, 1)).exists()


def test_deep_names_a_window_that_does_not_decode(tmp_path):
    path = store_of(tmp_path / "s")
    seg, off, _length = record_at(path, 12)
    patch_header(seg, off, codec=3)  # intact, but names another codec than its config
    assert check_store(str(path)).findings == []  # framing and checksums hold
    report = check_store(str(path), deep=True)
    (err,) = report.errors
    assert err.where == f"{segment_name(10)}@{off}" and "names codec 3" in err.what
    assert report.decoded == 29


def test_a_store_that_cannot_be_opened_is_one_error(tmp_path):
    path = store_of(tmp_path / "s")
    flip(path / MANIFEST, 14)
    (err,) = check_store(str(path)).findings
    assert err.severity == "error" and "MANIFEST is damaged" in err.what
