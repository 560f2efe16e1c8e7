"""The store's library API: puts, queries, validation, locking, failure handling."""

import json
import os

import pytest

import cclogfs
from cclogfs.errors import (
    InvalidInputError,
    StoreError,
    StoreFailedError,
    StoreLockedError,
    UnknownCodecError,
)
from cclogfs.store.fs import RecordingFileSystem


def msgs(t0, n, step=10, tag="x"):
    return [(t0 + i * step, json.dumps({"tag": tag, "i": i, "v": i * 0.1})) for i in range(n)]


def test_put_query_exact_round_trip(tmp_path):
    texts = ['{"a": 1.0}', '{"a":1e0 , "b" :[ ]}', '"\\u00e9\u00e9"', "  null ", '{"x": NaN}']
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/odom", list(zip(range(5), texts)), meta={"score": 3.1})
        (w,) = store.query("/odom")
        assert list(w.messages()) == list(zip(range(5), texts))
        assert (w.name, w.seq, w.start_ns, w.end_ns, w.count, w.meta) == ("/odom", 0, 0, 4, 5, {"score": 3.1})


@pytest.mark.parametrize("codec", ["none", "zstd", {"id": "lzma", "preset": 1}])
def test_codecs_per_store_per_stream_per_put(tmp_path, codec):
    with cclogfs.open_store(tmp_path / "s", create=True, codec=codec, stream_codecs={"/tf": "none"}) as store:
        store.put_window("/odom", msgs(0, 20))
        store.put_window("/tf", msgs(0, 20))
        store.put_window("/odom", msgs(500, 20), codec="lzma")
        got = {(w.name, w.seq): w.codec_config["id"] for w in store.query()}
    want_id = codec if isinstance(codec, str) else codec["id"]
    assert got == {("/odom", 0): want_id, ("/tf", 1): "none", ("/odom", 2): "lzma"}


def test_query_time_overlap_and_order(tmp_path):
    with cclogfs.open_store(tmp_path / "s", create=True, segment_bytes=4096) as store:
        for k in range(40):  # interleaved streams, several sealed segments
            store.put_window(f"/s{k % 2}", msgs(k * 100, 5, step=20))
            store.sync()
        assert len(store.sealed) >= 2
        ws = list(store.query("/s0", 1000, 1500))
        assert [w.start_ns for w in ws] == [1000, 1200, 1400]
        ws = list(store.query(None, 1050, 1150))  # 1000..1080 touches 1050; 1100..1180 too
        assert [(w.name, w.start_ns) for w in ws] == [("/s0", 1000), ("/s1", 1100)]
        assert [w.start_ns for w in store.query(None)] == sorted(w.start_ns for w in store.query(None))
        assert list(store.query("/nope")) == []
        assert list(store.query("/s0", 10**9, 2 * 10**9)) == []


def test_long_window_overlapping_many_short_ones(tmp_path):
    # The running max of end makes a long early window visible to a late query.
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/a", [(0, "1"), (10_000, "2")])
        for k in range(1, 50):
            store.put_window("/a", [(k * 100, "3")])
        assert [w.start_ns for w in store.query("/a", 9_000, 9_500)] == [0]


def test_flat_namespace_names_are_data(tmp_path):
    names = ["../../etc/passwd", "/odom", "a/b/../c", "\u00e9t\u00e9", "x" * 1024, "CON", ".", "MANIFEST"]
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        for i, name in enumerate(names):
            store.put_window(name, [(i, "{}")])
    assert sorted(os.listdir(tmp_path)) == ["s"]
    files = sorted(os.listdir(tmp_path / "s"))
    assert files == ["00000000000000000000.idx", "00000000000000000000.seg", "LOCK", "MANIFEST", "RESERVE"]
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert sorted(store.streams()) == sorted(names)


@pytest.mark.parametrize(
    "name, match",
    [("", "must not be empty"), ("a\x00b", "control character"), ("a\nb", "control character"),
     ("x" * 1025, "over the 1024-byte limit"), ("\ud800", "not valid UTF-8"), (b"/odom", "must be a str")],
)  # fmt: skip
def test_bad_stream_names(tmp_path, name, match):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        with pytest.raises(InvalidInputError, match=match):
            store.put_window(name, [(0, "{}")])


@pytest.mark.parametrize(
    "messages, match",
    [([], "at least one message"), ([(0, "{")], "message 0 is not well-formed JSON"),
     ([(0, "{}"), (1, "{} x")], "message 1 is not well-formed JSON"),
     ([(5, "1"), (4, "2")], "message 1: stamp_ns 4 is before"), ([(0.5, "1")], "must be an integer"),
     ([(True, "1")], "got a bool"), ([(1 << 63, "1")], "does not fit in 64 bits"),
     ([(0, b"{}")], "must be a str"), ([(0, '"\ud800"')], "not valid UTF-8"), ([(0,)], "not a")],
)  # fmt: skip
def test_bad_windows_store_nothing(tmp_path, messages, match):
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/ok", [(0, "{}")])
        with pytest.raises(InvalidInputError, match=match):
            store.put_window("/odom", messages)
        with pytest.raises(InvalidInputError, match="meta"):
            store.put_window("/odom", [(0, "{}")], meta={"x": object()})
        with pytest.raises(UnknownCodecError):
            store.put_window("/odom", [(0, "{}")], codec="bogus")
        assert [w.seq for w in store.query()] == [0]
        assert store.put_window("/odom", [(1, "{}")]).seq == 1  # no sequence number was used up


def test_one_writer_many_readers(tmp_path):
    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True, sync_every_ms=None, sync_every_bytes=None) as writer:
        writer.put_window("/a", [(0, "1")])
        writer.sync()
        writer.put_window("/a", [(1, "2")])  # buffered, not yet handed to the OS
        with pytest.raises(StoreLockedError, match=f"pid.*{os.getpid()}"):
            cclogfs.open_store(path)
        with cclogfs.open_store(path, readonly=True) as reader:
            assert [w.seq for w in reader.query()] == [0]
            with pytest.raises(StoreError, match="read-only"):
                reader.put_window("/a", [(2, "3")])
        assert [w.seq for w in writer.query()] == [0, 1]  # the writer sees its own puts
        with cclogfs.open_store(path, readonly=True) as reader:
            writer.sync()
            assert [w.seq for w in reader.query()] == [0]  # a snapshot of when it opened
            reader.refresh()
            assert [w.seq for w in reader.query()] == [0, 1]
    with cclogfs.open_store(path) as again:
        assert [w.seq for w in again.query()] == [0, 1]


def test_missing_and_foreign_directories(tmp_path):
    with pytest.raises(StoreError, match="not a cclogfs store"):
        cclogfs.open_store(tmp_path / "nope")
    (tmp_path / "junk").mkdir()
    (tmp_path / "junk" / "file.txt").write_text("hi")
    with pytest.raises(StoreError, match="holds files but no MANIFEST"):
        cclogfs.open_store(tmp_path / "junk", create=True)


def test_failed_fsync_refuses_further_writes(tmp_path):
    fs = RecordingFileSystem()
    store = cclogfs.open_store(tmp_path / "s", create=True, fs=fs, sync_every_ms=None)
    store.put_window("/a", [(0, "1")])
    store.sync()
    fs.fail_fsync = True
    store.put_window("/a", [(1, "2")])
    with pytest.raises(StoreFailedError, match="fsync failed"):
        store.sync()
    with pytest.raises(StoreFailedError, match="refuses further writes"):
        store.put_window("/a", [(2, "3")])
    store.close()
    with cclogfs.open_store(tmp_path / "s") as store:
        assert [w.seq for w in store.query()][:1] == [0]


def test_group_commit_policy(tmp_path):
    fs = RecordingFileSystem()

    def fsyncs():
        return sum(op[0] == "fsync" for op in fs.ops)

    with cclogfs.open_store(tmp_path / "a", create=True, fs=fs, sync_every_ms=None,
                            sync_every_bytes=2000) as store:  # fmt: skip
        base = fsyncs()
        for i in range(40):
            store.put_window("/a", msgs(i * 100, 3))
        per_group = fsyncs() - base
        assert 1 <= per_group < 40  # grouped, not one per put
    fs.ops.clear()
    with cclogfs.open_store(tmp_path / "b", create=True, fs=fs, sync_every_ms=0) as store:
        base = fsyncs()
        for i in range(10):
            store.put_window("/a", msgs(i * 100, 3))
        assert fsyncs() - base == 10


def test_time_based_group_commit_without_further_puts(tmp_path):
    import time

    fs = RecordingFileSystem()
    with cclogfs.open_store(tmp_path / "s", create=True, fs=fs, sync_every_ms=20,
                            sync_every_bytes=None) as store:  # fmt: skip
        store.put_window("/a", [(0, "1")])
        deadline = time.monotonic() + 5
        while not any(op[0] == "fsync" and op[1].endswith(".seg") for op in fs.ops[-3:]):
            assert time.monotonic() < deadline, "the group-commit thread never synced"
            time.sleep(0.01)


def test_closed_store(tmp_path):
    store = cclogfs.open_store(tmp_path / "s", create=True)
    store.close()
    store.close()
    with pytest.raises(StoreError, match="closed"):
        store.put_window("/a", [(0, "1")])
    with pytest.raises(StoreError, match="closed"):
        list(store.query())


def test_public_catalogue_api(tmp_path):
    # What upkeep, fsck and the CLI read instead of the store's private members.
    from cclogfs.store import SealedSegment

    path = tmp_path / "s"
    with cclogfs.open_store(path, create=True, segment_records=3, sync_every_ms=None) as store:
        for i in range(7):
            store.put_window("/a" if i % 2 else "/b", [(i * 10, "1"), (i * 10 + 1, "2")])
        sealed = store.sealed_segments()
        assert [(s.first_seq, s.end_seq, s.gen, s.aged) for s in sealed] == [(0, 3, 0, {}), (3, 6, 0, {})]
        assert all(isinstance(s, SealedSegment) for s in sealed)
        assert sealed[0].streams["/b"]["windows"] == 2 and sealed[0].streams["/a"]["messages"] == 2
        assert sealed[0].size == (path / "00000000000000000000.seg").stat().st_size
        assert store.active_first_seq == 6 and store.segment_count() == 3
        assert store.segment_first_seqs() == [0, 3, 6]
        assert [w.seq for w in store.segment_windows(6)] == [6]
        assert sorted(w.seq for w in store.segment_windows(3)) == [3, 4, 5]
        assert store.format_version == 3 and len(store.store_id) == 32
        store_id = store.store_id
    with cclogfs.open_store(path, readonly=True) as reader:
        assert reader.active_first_seq is None and reader.segment_count() == 3
        assert reader.store_id == store_id and reader.sealed_segments() == sealed
        assert [w.offset for w in reader.segment_windows(6)] == [32]


def test_a_store_is_created_complete_or_not_at_all(tmp_path, monkeypatch):
    # Issue 11, item 3: a creation killed before its manifest was durable.
    from cclogfs.store.fs import FileSystem

    def killed(self, src, dst):
        raise KeyboardInterrupt  # the process dies before the commit point

    monkeypatch.setattr(FileSystem, "rename", killed)
    with pytest.raises(KeyboardInterrupt):
        cclogfs.open_store(tmp_path / "s", create=True)
    monkeypatch.undo()
    assert not (tmp_path / "s").exists() and os.listdir(tmp_path) == []
    (tmp_path / "s").mkdir()  # a directory the user made first is fine too
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        store.put_window("/a", [(1, "1")])
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [w.seq for w in store.query()] == [0]


def test_a_half_made_store_is_finished_by_the_next_writer(tmp_path):
    # What an older version's killed creation left: a directory with only LOCK.
    (tmp_path / "s").mkdir()
    (tmp_path / "s" / "LOCK").write_text("")
    with pytest.raises(StoreError, match="creation was interrupted"):
        cclogfs.open_store(tmp_path / "s", readonly=True)
    with cclogfs.open_store(tmp_path / "s") as store:  # no create=True needed
        store.put_window("/a", [(1, "1")])
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        assert [w.seq for w in store.query()] == [0]


def test_a_store_path_that_is_a_file_is_a_store_error(tmp_path):
    # os.listdir raised NotADirectoryError: `cclog record x --store FILE` showed a traceback
    path = tmp_path / "afile"
    path.write_text("not a store\n")
    for kw in ({"create": True}, {"readonly": True}):
        with pytest.raises(StoreError, match="cannot open the store: Not a directory"):
            cclogfs.open_store(path, **kw)
    assert path.read_text() == "not a store\n"


def test_a_writer_whose_lock_file_was_removed_refuses_to_write(tmp_path):
    """Issue 16 item 7: LOCK unlinked while writer A holds it lets writer B lock a new file;
    A must notice before writing again, so B's records and A's synced ones both survive."""
    from cclogfs.errors import StoreFailedError

    path = tmp_path / "s"
    a = cclogfs.open_store(path, create=True, sync_every_ms=None)
    a.put_window("/a", [(1, '{"w": "a1"}')])
    a.sync()
    os.unlink(path / "LOCK")
    with cclogfs.open_store(path, sync_every_ms=None) as b:
        b.put_window("/b", [(2, '{"w": "b1"}')])
        b.sync()
    a.put_window("/a", [(3, '{"w": "a2"}')])
    with pytest.raises(StoreFailedError, match="LOCK.*removed or replaced"):
        a.sync()
    with pytest.raises(StoreFailedError):
        a.seal()
    a.close()
    with cclogfs.open_store(path, readonly=True) as store:
        got = [(w.name, list(w.messages())) for w in store.query()]
    assert got == [("/a", [(1, '{"w": "a1"}')]), ("/b", [(2, '{"w": "b1"}')])]


def test_lock_is_taken_again_when_the_file_was_replaced_meanwhile(tmp_path):
    from cclogfs.store.fs import FileSystem

    fs, lock = FileSystem(), str(tmp_path / "LOCK")
    fd = fs.lock(lock)
    assert fs.lock_held(fd, lock)
    os.unlink(lock)
    assert not fs.lock_held(fd, lock)
    fd2 = fs.lock(lock)  # a new file: this lock excludes the next writer again
    assert fd2 is not None and fs.lock_held(fd2, lock)
    os.replace(str(tmp_path / "LOCK"), str(tmp_path / "old"))
    assert not fs.lock_held(fd2, lock)
    fs.unlock(fd)
    fs.unlock(fd2)


def test_a_logging_window_whose_late_messages_land_in_a_later_part_reads_whole_and_in_order(tmp_path, capsys):
    """Found by attack: a recording's logging window emits each topic in parts of 10,000
    messages (classifier/windows.py, max_part); a message that arrives late, after its
    part went out, lands in a later part, whose start then lies inside the part before
    (two records of one stream overlapping in time). What a reader gets is what FORMAT.md
    ("Time index", Query) specifies: every window overlapping a range, in (start_ns, seq)
    order, each with its messages as put; stamp order across windows is the reader's
    merge, which `cclog cat` does."""
    from cclogfs.classifier.windows import WindowBuilder
    from cclogfs.cli import main
    from cclogfs.pipeline import RecordStats, store_window

    ms = 1_000_000
    wb = WindowBuilder(trigger_topic="/odom", before=2, after=20_000)
    out, sent, late = [], [], []
    for i in range(3):
        out += wb.push("/odom", i * 1000 * ms, "{}", anomalous=i == 2)
    for k in range(12_000):  # /scan follows /odom; every 1000th /scan arrives 11 s late
        out += wb.push("/odom", 4000 * ms + k * ms, "{}")
        stamp = 4000 * ms + k * ms - ms // 2
        (late if k % 1000 == 0 and k else sent).append(stamp)
        if not (k % 1000 == 0 and k):
            out += wb.push("/scan", stamp, json.dumps({"s": stamp}))
        if k == 11_000:
            for s in late:
                out += wb.push("/scan", s, json.dumps({"s": s}))
    out += wb.flush()
    sent += late
    with cclogfs.open_store(tmp_path / "s", create=True) as store:
        for w in out:
            store_window(store, w, RecordStats())
    with cclogfs.open_store(tmp_path / "s", readonly=True) as store:
        ws = list(store.query("/scan"))
        assert [w.meta["part"] for w in ws] == [0, 1] and ws[1].start_ns < ws[0].end_ns  # they overlap
        assert [(w.start_ns, w.seq) for w in ws] == sorted((w.start_ns, w.seq) for w in ws)
        got = [s for w in ws for s, _t in w.messages()]
        assert sorted(got) == sorted(sent) and got != sorted(got)  # complete; stamp order is a merge
        t0, t1 = 5999 * ms, 6001 * ms  # the late 5999.5 ms is in part 1 (from 4999.5 ms), 6000.5 in part 0
        hit = [s for w in store.query("/scan", t0, t1) for s, _t in w.messages() if t0 <= s <= t1]
        assert sorted(hit) == [5999 * ms + ms // 2, 6000 * ms + ms // 2]
    capsys.readouterr()
    assert main(["cat", str(tmp_path / "s"), "--topic", "/scan"]) == 0
    stamps = [json.loads(line)["stamp_ns"] for line in capsys.readouterr().out.splitlines()]
    assert stamps == sorted(sent)
