"""A reader opening while the writer appends (issue 16 item 1): it sees one snapshot.

The writer's appends reach a reader's view byte by byte (a page at a time, in any order of
the reader's calls). A reader must list exactly the records complete within the one size
it took for the segment, read every one it lists, and never count or read bytes past it:
they belong to a later snapshot, and a second look at the size made `fsck` call an append
in flight damage, and reads fall into a write buffer the reader does not have.
"""

import json

import pytest

import cclogfs
from cclogfs.errors import CorruptionError
from cclogfs.store.format import SEGMENT_HEADER_SIZE, Reason
from cclogfs.store.fs import FileSystem
from cclogfs.store.fsck import check_store
from cclogfs.store.segment import open_segment


class SegmentsSeen(FileSystem):
    """A file system that notes which descriptors are segment files (`segments`), for the
    views below that act only on segments."""

    def __init__(self):
        self.segments = set()

    def open(self, path, *, write=False, create=False):
        fd = super().open(path, write=write, create=create)
        if path.endswith(".seg"):
            self.segments.add(fd)
        return fd


class Growing(SegmentsSeen):
    """A reader's view of segment files that a writer is still appending to: every call the
    reader makes (size, read) lets `step` more bytes of the file become visible."""

    def __init__(self, visible: int, step: int, full: int):
        super().__init__()
        self.visible, self.step, self.full = visible, step, full

    def _tick(self) -> int:
        self.visible = min(self.full, self.visible + self.step)
        return self.visible

    def size(self, fd):
        return self._tick() if fd in self.segments else super().size(fd)

    def pread(self, fd, size, offset):
        if fd in self.segments:
            size = max(0, min(size, self._tick() - offset))
        return super().pread(fd, size, offset)

    def next_data(self, fd, offset):
        return offset


def _recording(path, n=12):
    """A store whose writer is still recording: records handed to the OS, no clean close."""
    writer = cclogfs.open_store(path, create=True, sync_every_ms=None, sync_every_bytes=None)
    offsets = []
    for i in range(n):
        receipt = writer.put_window("/a", [(i, json.dumps({"x": i, "pad": "p" * (7 * i)}))])
        offsets.append(receipt.stored_bytes)
    writer.active.flush()
    ends, pos = [], SEGMENT_HEADER_SIZE
    for length in offsets:
        pos += length
        ends.append(pos)
    return writer, ends


@pytest.mark.parametrize("step", [0, 61, 400])
def test_a_reader_opening_during_appends_sees_exactly_the_records_complete_in_its_snapshot(tmp_path, step):
    writer, ends = _recording(tmp_path / "s")
    full = ends[-1]
    false_errors = []
    for visible in range(SEGMENT_HEADER_SIZE, full, 89):
        fs = Growing(visible, step, full)
        with cclogfs.open_store(tmp_path / "s", readonly=True, fs=fs) as reader:
            seqs = [w.seq for w in reader.query()]
            for w in reader.query():
                list(w.messages())  # every window it lists reads back
            # The snapshot is the size taken when the segment was opened: the records
            # complete within it, all of them, and nothing counted past it.
            (seg,) = reader._segments()
            cut = sum(p.dropped_bytes for p in reader.recovery.problems)  # a record in flight
            assert seqs == list(range(sum(1 for e in ends if e <= seg.size + cut)))
            false_errors += [str(p) for p in reader.recovery.problems if p.intact_after]
        report = check_store(str(tmp_path / "s"), deep=True, fs=Growing(visible, step, full))
        false_errors += [str(f) for f in report.errors]
    writer.close()
    assert false_errors == []


def test_a_segment_is_never_read_past_the_size_its_store_saw(tmp_path):
    # A reader's segment has no write buffer: a record past its snapshot (an index or a
    # row that came from a later look at the file) is a one-line error naming the file and
    # offset, not a `zero fill` read out of an empty buffer.
    writer, ends = _recording(tmp_path / "s", n=3)
    path = str(tmp_path / "s" / "00000000000000000000.seg")
    seg, ok = open_segment(FileSystem(), path, write=False)
    try:
        assert ok and seg.size == ends[-1]
        writer.put_window("/a", [(99, "{}")])
        writer.active.flush()  # the file grows after the reader took its size
        with pytest.raises(CorruptionError, match=rf"{path}: record at offset {ends[-1]} .*past the "
                                                  rf"{ends[-1]} bytes") as err:  # fmt: skip
            seg.read_record(ends[-1], 100)
        assert err.value.offset == ends[-1] and err.value.reason == Reason.TORN
    finally:
        seg.fs.close(seg.fd)
        writer.close()


def test_fsck_while_the_writer_drops_and_rewrites_the_segments_it_checks(tmp_path, monkeypatch):
    # Found by `bench load`: fsck reopened each sealed segment by name, after the writer had
    # dropped or rewritten it (a raw FileNotFoundError). It checks the files it opened.
    from cclogfs.store import fsck
    from cclogfs.store.compaction import Replacement
    from cclogfs.store.format import RecordFlag

    writer = cclogfs.open_store(tmp_path / "s", create=True, sync_every_ms=None, segment_records=2)
    for i in range(8):
        writer.put_window("/a", [(i * 10 + k, json.dumps({"x": k})) for k in range(3)])
    writer.sync()
    checked = fsck._check_sealed

    def compacting(store, fs, report):
        writer.drop_oldest()
        first = writer.sealed_segments()[0].first_seq
        writer.rewrite(lambda w: Replacement(list(w.messages())[:1], {"aged": {"abs": 1}}, flags=RecordFlag.AGED),
                       segments=[first])  # fmt: skip
        checked(store, fs, report)

    monkeypatch.setattr(fsck, "_check_sealed", compacting)
    report = check_store(str(tmp_path / "s"), deep=True)
    writer.close()
    assert report.errors == [] and report.records == 8


class WriterActsOnce(SegmentsSeen):
    """A reader's file system that lets the writer act (`action`) once, when the reader
    first takes the size of a segment: after it read the manifest and listed the directory."""

    def __init__(self, action):
        super().__init__()
        self.action = action

    def size(self, fd):
        if fd in self.segments and self.action is not None:
            action, self.action = self.action, None
            action()
        return super().size(fd)


def _writer_with_windows(path, n=5):
    writer = cclogfs.open_store(path, create=True, sync_every_ms=None)
    for i in range(n):
        writer.put_window("/a", [(i, json.dumps({"x": i}))])
    writer.sync()
    return writer


def test_a_reader_keeps_its_open_when_the_writer_only_seals_meanwhile(tmp_path):
    # A seal replaces the manifest but leaves every file the reader opened whole: the reader
    # opened once, where it read the manifest and opened its segments twice before.
    writer = _writer_with_windows(tmp_path / "s")
    with cclogfs.open_store(tmp_path / "s", readonly=True, fs=WriterActsOnce(writer.seal)) as reader:
        assert reader.open_attempts == 1
        assert [w.seq for w in reader.query()] == list(range(5))
    writer.put_window("/a", [(9, "{}")])
    writer.close()


def test_a_reader_opens_again_when_the_writer_rewrites_its_tail_meanwhile(tmp_path):
    # Aging the segment the reader took as its tail deletes that file: had the reader listed
    # the directory a moment later, its log would have ended early. It reads the manifest again.
    from cclogfs.store.compaction import Replacement
    from cclogfs.store.format import RecordFlag

    writer = _writer_with_windows(tmp_path / "s")

    def seal_and_age():
        writer.seal()
        writer.rewrite(lambda w: Replacement(list(w.messages()), {"aged": {"abs": 1}}, flags=RecordFlag.AGED))

    with cclogfs.open_store(tmp_path / "s", readonly=True, fs=WriterActsOnce(seal_and_age)) as reader:
        assert reader.open_attempts == 2
        assert [(w.seq, bool(w.aged)) for w in reader.query()] == [(i, True) for i in range(5)]
    writer.close()
